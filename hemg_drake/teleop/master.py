"""Haptic master dynamics (eq. 19, master side): the Touch X stylus tip as a mass-damper.

Frame M is the device frame, centred in its workspace, with the OpenHaptics axes: x to the
operator's right, y up, z towards the operator. Point S is the stylus tip.
"""

import math

import numpy as np
from pydrake.systems.framework import LeafSystem
from scipy.linalg import expm

from hemg_drake.teleop._validate import as_scalar, as_vector

# Touch X figures (shared/facts/touch_x.md); all are constructor parameters.
TOUCH_X_MASS = 0.045  # kg, apparent mass at the tip (data sheet, unverified)
TOUCH_X_PEAK_FORCE = 7.9  # N, CHAI3D's maxLinearForce for the PHANTOM Desktop / Touch X
TOUCH_X_WORKSPACE = (0.16, 0.12, 0.12)  # m, width x height x depth (data sheet, unverified)


def saturate_norm(force, limit):
    """Scale ``force`` down to norm ``limit`` if it is longer, keeping its direction.

    Parameters
    ----------
    force : array, shape (3,)
    limit : float, >= 0

    Returns
    -------
    array, shape (3,)
    """
    norm = math.sqrt(force @ force)  # not np.linalg.norm: this runs at 1 kHz
    return force if norm <= limit else force * (limit / norm)


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
        # One row per mode (0 free, 1 beyond a wall): a00 a01 a10 a11 b0 b1 of the step.
        self._coefficients = np.array(
            [
                np.concatenate([A.ravel(), B_d.ravel()])
                for A, B_d in (
                    _zero_order_hold(free, B, self.period),
                    _zero_order_hold(wall, B, self.period),
                )
            ]
        )
        self._free_coefficients = self._coefficients[0].tolist()
        self._half_size = 0.5 * self.workspace_size

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
        force = hand_force + saturate_norm(motor_force, self.peak_force)
        if self.friction > 0.0:
            # The force that stops the tip within one free-space step; friction supplies
            # up to its limit of the difference (stick), else it slides at its limit.
            a11, b1 = self._coefficients[0, 3], self._coefficients[0, 5]
            force = force + saturate_norm(-a11 * v_MS / b1 - force, self.friction)
        p_wall = np.minimum(np.maximum(p_MS, -self._half_size), self._half_size)
        outside = p_MS != p_wall
        if outside.any():
            a00, a01, a10, a11, b0, b1 = self._coefficients[outside.astype(np.intp)].T
        else:  # the usual case, as plain floats
            a00, a01, a10, a11, b0, b1 = self._free_coefficients
        # Beyond a wall, -k (x - x_wall) = -k x + k x_wall: the constant joins the input.
        u = force + self.wall_stiffness * (p_wall * outside)
        return a00 * p_MS + a01 * v_MS + b0 * u, a10 * p_MS + a11 * v_MS + b1 * u


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
    force feedback without algebraic loops. A NaN or infinite input raises ValueError.

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
        state_index = self.DeclareDiscreteState(np.concatenate([p_initial, np.zeros(3)]))
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=self.dynamics.period, offset_sec=0.0, update=self._update
        )
        self._state_output = self.DeclareStateOutputPort("state", state_index)
        self._p_MS_output = self.DeclareVectorOutputPort(
            "p_MS", 3, self._calc_p_MS, prerequisites_of_calc={self.xd_ticket()}
        )
        self._v_MS_output = self.DeclareVectorOutputPort(
            "v_MS", 3, self._calc_v_MS, prerequisites_of_calc={self.xd_ticket()}
        )

    def _update(self, context, discrete_state):
        state = context.get_discrete_state_vector().CopyToVector()
        hand_force = as_vector("hand_force", self._hand_force_input.Eval(context), 3)
        motor_force = as_vector("motor_force", self._motor_force_input.Eval(context), 3)
        p_MS, v_MS = self.dynamics.step(state[:3], state[3:], hand_force, motor_force)
        discrete_state.set_value(np.concatenate([p_MS, v_MS]))

    def _calc_p_MS(self, context, output):
        output.SetFromVector(context.get_discrete_state_vector().value()[:3])

    def _calc_v_MS(self, context, output):
        output.SetFromVector(context.get_discrete_state_vector().value()[3:])
