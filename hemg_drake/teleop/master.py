"""Haptic master dynamics (eq. 19, master side): the Touch X stylus tip as a mass-damper.

Frame M is the device frame, centred in its workspace, with the OpenHaptics axes: x to the
operator's right, y up, z towards the operator. Point S is the stylus tip.
"""

import math

import numpy as np
from pydrake.systems.framework import LeafSystem
from scipy.linalg import expm

from hemg_drake._validate import all_finite, as_scalar, as_vector

# Touch X figures (docs/facts.md); all are constructor parameters.
TOUCH_X_MASS = 0.045  # kg, apparent mass at the tip (data sheet, unverified)
TOUCH_X_PEAK_FORCE = 7.9  # N, CHAI3D's maxLinearForce for the PHANTOM Desktop / Touch X
TOUCH_X_WORKSPACE = (0.16, 0.12, 0.12)  # m, width x height x depth (data sheet, unverified)


def saturate_norm(force, limit):
    """Scale ``force`` down to norm ``limit`` if it is longer, keeping its direction.

    Plain floats, not numpy: this runs several times per 1 kHz step, where numpy's per-call
    overhead on 3-vectors costs more than the arithmetic (the results are the same to the bit).

    Parameters
    ----------
    force : sequence of 3 floats (list or array, shape (3,))
    limit : float, >= 0

    Returns
    -------
    list of 3 floats
    """
    x, y, z = force
    norm = math.sqrt(x * x + y * y + z * z)
    if norm <= limit:
        return [x, y, z]
    scale = limit / norm
    return [x * scale, y * scale, z * scale]


def _zero_order_hold(A, B, period):
    """Exact discretisation (A_d, B_d) of xdot = A x + B u with u held over ``period``."""
    n, m = B.shape
    augmented = np.zeros((n + m, n + m))
    augmented[:n, :n] = A
    augmented[:n, n:] = B
    transition = expm(augmented * period)
    return transition[:n, :n], transition[:n, n:]


class MasterDynamics:
    """One sample of the stylus-tip dynamics: the numpy twin of :class:`HapticMaster`.

    Each axis of M is an independent mass-damper, m xddot + b xdot = F (eq. 19 with the
    point-mass, constant-inertia, gravity-compensated stand-in of the facts file). Beyond a
    face of the workspace box a soft wall adds a spring-damper, k (x - x_wall) + c xdot.
    Both modes are discretised exactly (zero-order hold); the mode of each axis is chosen
    from the position at the start of the sample.

    Parameters
    ----------
    mass : float
        Apparent mass at the tip (kg).
    damping : float
        Viscous backdrive damping b (N s/m). Not published; a small value is assumed.
    friction : float
        Coulomb backdrive friction (N). The facts file's 0.06 N is unverified, so the
        default is 0 (linear device). Modelled per sample: the friction force is the force
        that would stop the tip within the sample, capped in norm at ``friction``.
    peak_force : float
        Motor force limit (N); the motor command is saturated in norm, so its direction is
        kept (one limit for the force vector, not per axis).
    workspace_size : array, shape (3,)
        Edge lengths of the workspace box centred on M's origin (m).
    wall_stiffness, wall_damping : float
        Soft-wall spring (N/m) and damper (N s/m) beyond the box. The default 5000 N/m
        holds a 10 N push within 2 mm of the wall; with the default 20 N s/m and 45 g the
        wall is about critically damped (zeta = 0.67).
    period : float
        Sample period (s); the haptic loop runs at 1 kHz.
    """

    def __init__(
        self,
        *,
        mass=TOUCH_X_MASS,
        damping=0.1,
        friction=0.0,
        peak_force=TOUCH_X_PEAK_FORCE,
        workspace_size=TOUCH_X_WORKSPACE,
        wall_stiffness=5000.0,
        wall_damping=20.0,
        period=1e-3,
    ):
        self.mass = as_scalar("mass", mass)
        self.damping = as_scalar("damping", damping, strict=False)
        self.friction = as_scalar("friction", friction, strict=False)
        self.peak_force = as_scalar("peak_force", peak_force, strict=False)
        self.workspace_size = as_vector("workspace_size", workspace_size, 3)
        if np.any(self.workspace_size <= 0):
            raise ValueError(f"workspace_size must be positive, got {self.workspace_size}")
        self.wall_stiffness = as_scalar("wall_stiffness", wall_stiffness, strict=False)
        self.wall_damping = as_scalar("wall_damping", wall_damping, strict=False)
        self.period = as_scalar("period", period)
        B = np.array([[0.0], [1.0 / self.mass]])
        free = np.array([[0.0, 1.0], [0.0, -self.damping / self.mass]])
        wall = np.array(
            [
                [0.0, 1.0],
                [
                    -self.wall_stiffness / self.mass,
                    -(self.damping + self.wall_damping) / self.mass,
                ],
            ]
        )
        # One row of plain floats per mode, indexed by "beyond a wall" (False 0, True 1):
        # a00 a01 a10 a11 b0 b1 of the step.
        self._mode_coefficients = [
            np.concatenate([A.ravel(), B_d.ravel()]).tolist()
            for A, B_d in (
                _zero_order_hold(free, B, self.period),
                _zero_order_hold(wall, B, self.period),
            )
        ]
        self._free_coefficients = self._mode_coefficients[0]
        self._half_size = (0.5 * self.workspace_size).tolist()

    def step(self, p_MS, v_MS, hand_force, motor_force):
        """Advance the tip by one period under forces held constant over it.

        Parameters
        ----------
        p_MS, v_MS : array, shape (3,)
            Tip position (m) and velocity (m/s) in M at the start of the sample.
        hand_force, motor_force : array, shape (3,)
            Operator's force and motor command on the tip, in M (N).

        Returns
        -------
        p_MS, v_MS : array, shape (3,)
            At the end of the sample.
        """
        p_next, v_next = self.step_floats(
            list(map(float, p_MS)),
            list(map(float, v_MS)),
            list(map(float, hand_force)),
            list(map(float, motor_force)),
        )
        return np.array(p_next), np.array(v_next)

    def step_floats(self, p_MS, v_MS, hand_force, motor_force):
        """:meth:`step` on lists of 3 floats, returning two lists (what the system runs)."""
        force = [h + m for h, m in zip(hand_force, saturate_norm(motor_force, self.peak_force))]
        if self.friction > 0.0:
            # The force that stops the tip within one free-space step; friction supplies
            # up to its limit of the difference (stick), else it slides at its limit.
            a11, b1 = self._free_coefficients[3], self._free_coefficients[5]
            stop = [-a11 * v / b1 - f for v, f in zip(v_MS, force)]
            force = [f + s for f, s in zip(force, saturate_norm(stop, self.friction))]
        p_next, v_next = [], []
        for p, v, f, half in zip(p_MS, v_MS, force, self._half_size):
            p_wall = min(max(p, -half), half)
            outside = p != p_wall
            a00, a01, a10, a11, b0, b1 = self._mode_coefficients[outside]
            # Beyond a wall, -k (x - x_wall) = -k x + k x_wall: the constant joins the input.
            u = f + self.wall_stiffness * (p_wall * outside)
            p_next.append(a00 * p + a01 * v + b0 * u)
            v_next.append(a10 * p + a11 * v + b1 * u)
        return p_next, v_next


class HapticMaster(LeafSystem):
    """The Touch X stylus tip as a discrete 3-DOF mass-damper with soft workspace walls.

    .. pydrake_system::

        name: HapticMaster
        input_ports:
        - hand_force
        - motor_force
        output_ports:
        - state
        - p_MS
        - v_MS

    Implements the master side of eq. 19, M_m xddot_m + C_m xdot_m + G_m = F_m, for the
    tip as a point mass with constant apparent mass, viscous damping and gravity
    compensated by the device (see :class:`MasterDynamics`, which does the maths and takes
    the same keyword parameters, plus ``p_MS_initial``, the tip's rest position in M, m).

    Ports, all in frame M, SI units: ``hand_force`` (3, N) the operator's force on the
    stylus; ``motor_force`` (3, N) the motor command, saturated in norm at ``peak_force``;
    ``state`` (6) = [p_MS; v_MS]; ``p_MS`` (3, m) and ``v_MS`` (3, m/s) the tip.

    Timing: a periodic discrete update every ``period`` (1 ms) samples both inputs and
    holds them for the period. The update is an exact zero-order-hold discretisation of
    the mass-damper, so a step response equals the analytic solution to round-off at the
    sample instants. The device is a 1 kHz sampled system and the slave plant steps at
    1 ms too; a continuous state would instead force an error-controlled integrator on the
    whole diagram for a 45 g mass whose walls are stiff. The outputs depend on the state
    only (no direct feedthrough), so the master closes loops with the operator and the
    force feedback without algebraic loops; ``p_MS`` and ``v_MS`` are two discrete-state
    groups, output as they are. A NaN or infinite input raises ValueError.

    Modelling choices: the walls' damper acts whenever the tip is beyond a wall (on the way
    out too); the Touch X's continuous-force rating (1.75 N, a thermal limit over minutes)
    is not enforced, only the peak force.
    """

    def __init__(self, *, p_MS_initial=(0.0, 0.0, 0.0), **dynamics_parameters):
        LeafSystem.__init__(self)
        self.dynamics = MasterDynamics(**dynamics_parameters)
        p_initial = as_vector("p_MS_initial", p_MS_initial, 3)
        self._hand_force_input = self.DeclareVectorInputPort("hand_force", 3)
        self._motor_force_input = self.DeclareVectorInputPort("motor_force", 3)
        # p_MS and v_MS in two state groups: their output ports are then the state itself.
        self._p_index = self.DeclareDiscreteState(p_initial)
        self._v_index = self.DeclareDiscreteState(np.zeros(3))
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=self.dynamics.period, offset_sec=0.0, update=self._update
        )
        self._state_output = self.DeclareVectorOutputPort(
            "state", 6, self._calc_state, prerequisites_of_calc={self.xd_ticket()}
        )
        self._p_MS_output = self.DeclareStateOutputPort("p_MS", self._p_index)
        self._v_MS_output = self.DeclareStateOutputPort("v_MS", self._v_index)

    def _update(self, context, discrete_state):
        p_MS = context.get_discrete_state(self._p_index).value().tolist()
        v_MS = context.get_discrete_state(self._v_index).value().tolist()
        hand_force = self._hand_force_input.Eval(context).tolist()
        motor_force = self._motor_force_input.Eval(context).tolist()
        for name, force in (("hand_force", hand_force), ("motor_force", motor_force)):
            if not all_finite(force):
                raise ValueError(f"{name} must be finite, got {force}")
        p_MS, v_MS = self.dynamics.step_floats(p_MS, v_MS, hand_force, motor_force)
        discrete_state.set_value(self._p_index, p_MS)
        discrete_state.set_value(self._v_index, v_MS)

    def _calc_state(self, context, output):
        p_MS = context.get_discrete_state(self._p_index).value()
        v_MS = context.get_discrete_state(self._v_index).value()
        output.SetFromVector(np.concatenate([p_MS, v_MS]))
