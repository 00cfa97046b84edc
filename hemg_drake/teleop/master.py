"""Haptic master dynamics (eq. 19, master side): the Touch X stylus tip as a mass-damper.

Frame M is the device frame, centred in its workspace, with the OpenHaptics axes: x to the
operator's right, y up, z towards the operator. Point S is the stylus tip.
"""

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import sqrt as drake_sqrt
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector_, Context_, LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem
from scipy.linalg import expm

from hemg_drake._validate import all_finite, as_scalar, as_vector
from hemg_drake.teleop.config import MasterConfig

# The Touch X figures are MasterConfig's defaults; these names are for the browser's
# virtual device, which draws the same box.
TOUCH_X_PEAK_FORCE = MasterConfig().peak_force  # N
TOUCH_X_WORKSPACE = tuple(MasterConfig().workspace_size)  # m, width x height x depth

# Resolved once: a template lookup per call would cost microseconds at 1 kHz.
_DOUBLE_CONTEXT = Context_[float]
# The master's numeric parameter, in this order (SI units, MasterConfig's fields).
MASTER_PARAMETERS = ("mass", "damping", "friction", "peak_force", "wall_stiffness", "wall_damping")


def saturate_norm(force, limit):
    """Scale ``force`` down to norm ``limit`` if it is longer, keeping its direction.

    Scalar-type agnostic (floats or AutoDiffXd): the norm is compared squared, so a zero
    force has a finite derivative (the square root is taken only when saturating, where the
    norm exceeds ``limit`` > 0). Plain Python arithmetic on 3 elements: at 1 kHz numpy's
    per-call overhead on 3-vectors costs more than the arithmetic.

    Parameters
    ----------
    force : sequence of 3 scalars (list or array, shape (3,)), N
    limit : float, >= 0, N

    Returns
    -------
    list of 3 scalars
    """
    x, y, z = force
    squared = x * x + y * y + z * z
    if squared <= limit * limit:
        return [x, y, z]
    norm = math.sqrt(squared) if isinstance(squared, float) else drake_sqrt(squared)
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


def _checked_config(config):
    """The master's settings as checked floats (ValueError naming the field)."""
    if not isinstance(config, MasterConfig):
        raise ValueError(f"config must be a MasterConfig, got {type(config).__name__}")
    values = {
        "mass": as_scalar("mass", config.mass),
        "period": as_scalar("period", config.period),
        "workspace_size": as_vector("workspace_size", config.workspace_size, 3),
    }
    for name in ("damping", "friction", "peak_force", "wall_stiffness", "wall_damping"):
        values[name] = as_scalar(name, getattr(config, name), strict=False)
    if np.any(values["workspace_size"] <= 0):
        raise ValueError(f"workspace_size must be positive, got {values['workspace_size']}")
    return values


def mode_coefficients(mass, damping, wall_stiffness, wall_damping, period):
    """Coefficients of one sample of an axis, free and beyond a wall.

    Returns
    -------
    list of two lists [a00, a01, a10, a11, b0, b1]: the exact zero-order-hold step
    [p'; v'] = [[a00, a01], [a10, a11]] [p; v] + [b0; b1] u of m xddot + b xdot = u
    (index 0), and of m xddot + (b + c) xdot + k x = u (index 1).
    """
    B = np.array([[0.0], [1.0 / mass]])
    free = np.array([[0.0, 1.0], [0.0, -damping / mass]])
    wall = np.array(
        [[0.0, 1.0], [-wall_stiffness / mass, -(damping + wall_damping) / mass]]
    )
    return [
        np.concatenate([A_d.ravel(), B_d.ravel()]).tolist()
        for A_d, B_d in (_zero_order_hold(free, B, period), _zero_order_hold(wall, B, period))
    ]


def _state_vector(context, index):
    """Discrete state group ``index`` as an array: a view for double, a copy for
    AutoDiffXd (whose object arrays pydrake cannot reference)."""
    group = context.get_discrete_state(index)
    return group.value() if isinstance(context, _DOUBLE_CONTEXT) else group.CopyToVector()


@TemplateSystem.define("HapticMaster_", T_list=[float, AutoDiffXd])
def HapticMaster_(T):
    class Impl(LeafSystem_[T]):
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

        Implements the master side of eq. 19, M_m xddot_m + C_m xdot_m + G_m = F_m, for
        the tip as a point mass with constant apparent mass, viscous damping and gravity
        compensated by the device: each axis of M is an independent mass-damper,
        m xddot + b xdot = F. Beyond a face of the workspace box a soft wall adds a
        spring-damper, k (x - x_wall) + c xdot (the mode of each axis is chosen from the
        position at the start of the sample). Coulomb friction (``config.friction``, 0 by
        default) is the force that would stop the tip within the sample, capped in norm.

        Ports, all in frame M, SI units: ``hand_force`` (3, N) the operator's force on the
        stylus; ``motor_force`` (3, N) the motor command, saturated in norm at
        ``config.peak_force`` (its direction kept); ``state`` (6) = [p_MS; v_MS];
        ``p_MS`` (3, m) and ``v_MS`` (3, m/s) the tip.

        Timing: a periodic discrete update every ``config.period`` (1 ms) samples both
        inputs and holds them for the period. The update is an exact zero-order-hold
        discretisation of the mass-damper, so a step response equals the analytic solution
        to round-off at the sample instants. The outputs depend on the state only (no
        direct feedthrough), so the master closes loops with the operator and the force
        feedback without algebraic loops. A NaN or infinite input raises ValueError.

        Parameters in the Context: one numeric parameter ``MASTER_PARAMETERS`` (mass,
        damping, friction, peak_force, wall_stiffness, wall_damping), defaults from
        ``config``; :meth:`set_parameters` / :meth:`get_parameters`. The exact
        discretisation (``expm``) is a cache entry that depends on that parameter only, so
        it is recomputed when the parameter changes, not per step; under AutoDiffXd the
        parameters enter as constants (their values). The workspace box and the period are
        structural.

        Scalar types: double and AutoDiffXd (``ToAutoDiffXd()``, ``Clone()``), so the
        teleoperation loop can be linearised; the wall and saturation switches are
        piecewise, their derivative that of the active piece.

        Parameters
        ----------
        config : MasterConfig
            Mass (kg), damping (N s/m), friction (N), peak force (N), workspace box (m),
            wall spring (N/m) and damper (N s/m), period (s).
        p_MS_initial : array, shape (3,)
            The tip's rest position in M (m).
        """

        def _construct(self, *, config=MasterConfig(), p_MS_initial=(0.0, 0.0, 0.0),
                       converter=None):  # fmt: skip
            LeafSystem_[T].__init__(self, converter)
            self._config = config
            self._p_MS_initial = as_vector("p_MS_initial", p_MS_initial, 3)
            values = _checked_config(config)
            self._period = values["period"]
            self._half_size = (0.5 * values["workspace_size"]).tolist()
            self._parameter = self.DeclareNumericParameter(
                BasicVector_[T]([values[name] for name in MASTER_PARAMETERS])
            )
            # (coefficients of both modes, friction, peak force, wall stiffness) as floats,
            # recomputed (expm) only when the parameter changes.
            self._law = self.DeclareCacheEntry(
                "law",
                ValueProducer(allocate=lambda: AbstractValue.Make(()), calc=self._calc_law),
                {self.all_parameters_ticket()},
            )
            self._hand_force_input = self.DeclareVectorInputPort("hand_force", 3)
            self._motor_force_input = self.DeclareVectorInputPort("motor_force", 3)
            # p_MS and v_MS in two state groups: their output ports are the state itself.
            self._p_index = self.DeclareDiscreteState(self._p_MS_initial)
            self._v_index = self.DeclareDiscreteState(np.zeros(3))
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=values["period"], offset_sec=0.0, update=self._update
            )
            self.DeclareVectorOutputPort(
                "state", 6, self._calc_state, prerequisites_of_calc={self.xd_ticket()}
            )
            self.DeclareStateOutputPort("p_MS", self._p_index)
            self.DeclareStateOutputPort("v_MS", self._v_index)

        def _construct_copy(self, other, converter=None):
            Impl._construct(
                self, config=other._config, p_MS_initial=other._p_MS_initial,
                converter=converter,
            )  # fmt: skip

        def set_parameters(self, context, **values):
            """Write ``MASTER_PARAMETERS`` given by keyword (SI units) into ``context``
            (this system's own, e.g. ``master.GetMyMutableContextFromRoot(root)``)."""
            parameter = context.get_mutable_numeric_parameter(self._parameter)
            for name, value in values.items():
                if name not in MASTER_PARAMETERS:
                    raise ValueError(f"unknown master parameter {name!r}: {MASTER_PARAMETERS}")
                value = as_scalar(name, value, strict=name == "mass")
                parameter.SetAtIndex(MASTER_PARAMETERS.index(name), value)

        def get_parameters(self, context):
            """``MASTER_PARAMETERS`` of ``context`` as a dict of floats."""
            values = context.get_numeric_parameter(self._parameter).CopyToVector()
            return {name: _value(x) for name, x in zip(MASTER_PARAMETERS, values)}

        def _calc_law(self, context, value):
            mass, damping, friction, peak_force, wall_stiffness, wall_damping = (
                self.get_parameters(context).values()
            )
            coefficients = mode_coefficients(
                mass, damping, wall_stiffness, wall_damping, self._period
            )
            value.set_value((coefficients, friction, peak_force, wall_stiffness))

        def _step(self, law, p_MS, v_MS, hand_force, motor_force):
            """One sample of the tip from lists of 3 scalars and the cached ``law``
            (coefficients, friction, peak force, wall stiffness); returns (p_MS, v_MS)."""
            coefficients, friction, peak_force, wall_stiffness = law
            motor = saturate_norm(motor_force, peak_force)
            force = [h + m for h, m in zip(hand_force, motor)]
            if friction > 0.0:
                # The force that stops the tip within one free-space step; friction supplies
                # up to its limit of the difference (stick), else it slides at its limit.
                free = coefficients[0]
                a11, b1 = free[3], free[5]
                stop = [-a11 * v / b1 - f for v, f in zip(v_MS, force)]
                force = [f + s for f, s in zip(force, saturate_norm(stop, friction))]
            p_next, v_next = [], []
            for p, v, f, half in zip(p_MS, v_MS, force, self._half_size):
                outside = p > half or p < -half
                a00, a01, a10, a11, b0, b1 = coefficients[outside]
                if outside:
                    # -k (x - x_wall) = -k x + k x_wall: the constant joins the input.
                    f = f + wall_stiffness * (half if p > half else -half)
                p_next.append(a00 * p + a01 * v + b0 * f)
                v_next.append(a10 * p + a11 * v + b1 * f)
            return p_next, v_next

        def _update(self, context, discrete_state):
            hand_force = self._hand_force_input.Eval(context).tolist()
            motor_force = self._motor_force_input.Eval(context).tolist()
            if T == float:
                for name, force in (("hand_force", hand_force), ("motor_force", motor_force)):
                    if not all_finite(force):
                        raise ValueError(f"{name} must be finite, got {force}")
            if T is float:  # views: no copy, no array built (this is the 1 kHz path)
                p_MS = context.get_discrete_state(self._p_index).value().tolist()
                v_MS = context.get_discrete_state(self._v_index).value().tolist()
            else:
                p_MS = context.get_discrete_state(self._p_index).CopyToVector().tolist()
                v_MS = context.get_discrete_state(self._v_index).CopyToVector().tolist()
            law = self._law.Eval(context)  # cached: recomputed when the parameter changes
            p_MS, v_MS = self._step(law, p_MS, v_MS, hand_force, motor_force)
            if T is float:
                discrete_state.get_mutable_value(self._p_index)[:] = p_MS
                discrete_state.get_mutable_value(self._v_index)[:] = v_MS
            else:
                discrete_state.set_value(self._p_index, np.array(p_MS, dtype=object))
                discrete_state.set_value(self._v_index, np.array(v_MS, dtype=object))

        def _calc_state(self, context, output):
            p_MS = _state_vector(context, self._p_index)
            v_MS = _state_vector(context, self._v_index)
            output.SetFromVector(np.concatenate([p_MS, v_MS]))

    return Impl


HapticMaster = HapticMaster_[None]


def _value(x):
    """A parameter as a float (its AutoDiffXd value: the law's constants are not inputs)."""
    return x.value() if isinstance(x, AutoDiffXd) else float(x)
