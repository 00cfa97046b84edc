"""A simulated human operator: pushes the stylus along a task plan and tenses the arm."""

import math

import numpy as np
from pydrake.systems.framework import LeafSystem

from hemg_drake.tasks.plan import TaskPlan
from hemg_drake._validate import all_finite, as_scalar
from hemg_drake.teleop.mapping import WorkspaceMapping
from hemg_drake.teleop.master import saturate_norm

# The hand's default impedance and force limit (OperatorModel's parameters explain them);
# the browser's virtual hand takes the same.
HAND_STIFFNESS = 300.0  # N/m
HAND_DAMPING = 5.0  # N s/m
MAX_HAND_FORCE = 15.0  # N


def hand_impedance_force(p_target, v_target, p_MS, v_MS, *, stiffness, damping, max_force):
    """The hand's force on the stylus, an impedance towards a target (eq. 19's F_h):
    F_h = sat(K_h (p_target - p_MS) + D_h (v_target - v_MS), max_force), saturated in norm.

    Parameters
    ----------
    p_target, v_target : 3 floats each, m and m/s, where the hand heads for, in M.
    p_MS, v_MS : 3 floats each, m and m/s, the stylus tip in M.
    stiffness, damping : float, K_h (N/m) and D_h (N s/m).
    max_force : float, N.

    Returns
    -------
    list of 3 floats, N, in M. Plain floats: this runs at the master's 1 kHz.
    """
    force = [
        stiffness * (pt - p) + damping * (vt - v)
        for pt, p, vt, v in zip(p_target, p_MS, v_target, v_MS)
    ]
    return saturate_norm(force, max_force)


class OperatorModel:
    """The operator's hand and muscle laws: the numpy twin of :class:`SimulatedOperator`.

    Hand: an impedance towards the plan mapped into the master frame M,
    F_h = K_h (p_MSplan(t) - p_MS) + D_h (v_MSplan(t) - v_MS), saturated in norm.
    Muscle: a first-order activation a towards the target
    a* = clip(a_rest + effort (a_level - a_rest) + g_cc |f_felt|, 0, 1), where a_level is the
    free or forceful level of the plan's current segment (a_rest before and after the plan),
    effort the segment's effort scale, and g_cc |f_felt| the co-contraction with which a
    human stiffens the arm against a felt force.

    Parameters
    ----------
    plan : TaskPlan
        What the operator wants the slave to do (world frame).
    mapping : WorkspaceMapping
        Used backwards, to find where the stylus must be for the slave to be on the plan.
    hand_stiffness : float
        K_h (N/m). The relaxed human arm's endpoint stiffness is of the order of a few
        hundred N/m (Mussa-Ivaldi, Hogan and Bizzi 1985); 300 sits in the 200-400 range.
    hand_damping : float
        D_h (N s/m); 5 gives the 45 g tip a damping ratio near 0.7 with 300 N/m.
    max_hand_force : float
        Saturation of the hand force's norm (N); 15 N is a firm pinch-and-push on a stylus.
    rest_activation, free_activation, forceful_activation : float
        Activation levels in [0, 1]: relaxed, moving freely, working against the task.
    co_contraction_gain : float
        Activation added per newton of felt force (1/N).
    activation_time_constant : float
        Muscle activation time constant (s); 30-50 ms is typical of activation dynamics.
    period : float
        Sample period of the activation (s): the MYO's 1/200 s, the rate at which the sEMG
        source reads it (a faster update would be computed and never seen).
    """

    def __init__(
        self,
        *,
        plan,
        mapping,
        hand_stiffness=HAND_STIFFNESS,
        hand_damping=HAND_DAMPING,
        max_hand_force=MAX_HAND_FORCE,
        rest_activation=0.05,
        free_activation=0.2,
        forceful_activation=0.7,
        co_contraction_gain=0.05,
        activation_time_constant=0.04,
        period=0.005,
    ):
        if not isinstance(plan, TaskPlan):
            raise ValueError(f"plan must be a TaskPlan, got {type(plan).__name__}")
        if not isinstance(mapping, WorkspaceMapping):
            raise ValueError(f"mapping must be a WorkspaceMapping, got {type(mapping).__name__}")
        self.plan = plan
        self.mapping = mapping
        # The plan mapped into M once (the map is affine), rather than every sample.
        self._plan_M = plan.in_frame(mapping.slave_to_master(plan.points))
        self.hand_stiffness = as_scalar("hand_stiffness", hand_stiffness, strict=False)
        self.hand_damping = as_scalar("hand_damping", hand_damping, strict=False)
        self.max_hand_force = as_scalar("max_hand_force", max_hand_force, strict=False)
        self.levels = {}
        for name, level in (
            ("rest", rest_activation),
            ("free", free_activation),
            ("forceful", forceful_activation),
        ):
            level = as_scalar(f"{name}_activation", level, strict=False)
            if level > 1.0:
                raise ValueError(f"{name}_activation must be in [0, 1], got {level}")
            self.levels[name] = level
        self.co_contraction_gain = as_scalar(
            "co_contraction_gain", co_contraction_gain, strict=False
        )
        self.activation_time_constant = as_scalar(
            "activation_time_constant", activation_time_constant
        )
        self.period = as_scalar("period", period)
        # Exact discretisation of a' = (a* - a) / tau with a* held over the period.
        self._decay = math.exp(-self.period / self.activation_time_constant)

    def hand_force(self, t, p_MS, v_MS):
        """Force (N, in M, shape (3,)) the hand puts on the stylus at time t (s)."""
        return np.array(self.hand_force_floats(t, list(p_MS), list(v_MS)))

    def hand_force_floats(self, t, p_MS, v_MS):
        """:meth:`hand_force` with ``p_MS``, ``v_MS`` and the result as lists of 3 floats."""
        p_target, v_target = self._plan_M.position_velocity_floats(t)
        return hand_impedance_force(
            p_target, v_target, p_MS, v_MS, stiffness=self.hand_stiffness,
            damping=self.hand_damping, max_force=self.max_hand_force,
        )  # fmt: skip

    def activation_target(self, t, feedback_force):
        """Activation a* the muscles head for at time t (s) feeling ``feedback_force`` (N)."""
        rest = self.levels["rest"]
        if self.plan.start_time <= t <= self.plan.end_time:
            segment = self.plan.segment(t)
            level = rest + segment.effort * (self.levels[segment.kind] - rest)
        else:
            level = rest
        x, y, z = feedback_force
        felt = self.co_contraction_gain * math.sqrt(x * x + y * y + z * z)
        return min(max(level + felt, 0.0), 1.0)

    def activation_step(self, t, activation, feedback_force):
        """Activation one period after time t (s), from ``activation`` at t."""
        target = self.activation_target(t, feedback_force)
        return target + (activation - target) * self._decay


class SimulatedOperator(LeafSystem):
    """A human stand-in: hand force on the stylus and muscle activation, from a task plan.

    .. pydrake_system::

        name: SimulatedOperator
        input_ports:
        - p_MS
        - v_MS
        - feedback_force
        output_ports:
        - hand_force
        - activation

    The laws and parameters are those of :class:`OperatorModel` (same keyword arguments).
    Ports: ``p_MS`` (3, m), ``v_MS`` (3, m/s) the stylus tip in M; ``feedback_force``
    (3, N, in M) the force the hand feels from the device motors (the HapticMaster's
    ``motor_force`` input); ``hand_force`` (3, N, in M) for the HapticMaster's
    ``hand_force``; ``activation`` (1, in [0, 1]) for the synthetic EMG source.

    Timing: the hand is a continuous impedance, so ``hand_force`` is a direct feedthrough
    of ``p_MS``, ``v_MS`` and the time (not of ``feedback_force``); the discrete
    HapticMaster samples it without an extra delay. The activation is discrete state,
    updated every ``period`` (5 ms) by the exact discretisation of the first-order muscle
    lag, and starts at the rest level. Human variability comes from the plan: give each
    demonstration its own ``plan.perturbed(seed)``. Start the HapticMaster at the plan's
    first point mapped into M (``mapping.slave_to_master(plan.points[0])``) to avoid an
    initial jerk, and keep the mapped plan inside the master's workspace. NaN inputs raise
    ValueError.
    """

    def __init__(self, **model_parameters):
        LeafSystem.__init__(self)
        self.model = OperatorModel(**model_parameters)
        self._p_MS_input = self.DeclareVectorInputPort("p_MS", 3)
        self._v_MS_input = self.DeclareVectorInputPort("v_MS", 3)
        self._feedback_force_input = self.DeclareVectorInputPort("feedback_force", 3)
        activation_index = self.DeclareDiscreteState([self.model.levels["rest"]])
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=self.model.period, offset_sec=0.0, update=self._update
        )
        self._hand_force_output = self.DeclareVectorOutputPort(
            "hand_force",
            3,
            self._calc_hand_force,
            prerequisites_of_calc={
                self.time_ticket(),
                self._p_MS_input.ticket(),
                self._v_MS_input.ticket(),
            },
        )
        self._activation_output = self.DeclareStateOutputPort("activation", activation_index)

    def _input_floats(self, context, name, port):
        values = port.Eval(context).tolist()
        if not all_finite(values):
            raise ValueError(f"{name} must be finite, got {values}")
        return values

    def _calc_hand_force(self, context, output):
        p_MS = self._input_floats(context, "p_MS", self._p_MS_input)
        v_MS = self._input_floats(context, "v_MS", self._v_MS_input)
        output.SetFromVector(self.model.hand_force_floats(context.get_time(), p_MS, v_MS))

    def _update(self, context, discrete_state):
        feedback_force = self._input_floats(context, "feedback_force", self._feedback_force_input)
        activation = context.get_discrete_state_vector().GetAtIndex(0)
        discrete_state.set_value(
            [self.model.activation_step(context.get_time(), activation, feedback_force)]
        )
