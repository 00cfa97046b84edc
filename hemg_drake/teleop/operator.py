"""A simulated human operator: pushes the stylus along a task plan and tenses the arm."""

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common import RandomDistribution
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import Context_, Diagram, DiagramBuilder, LeafSystem_
from pydrake.systems.primitives import RandomSource
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake._validate import all_finite, as_scalar, as_vector
from hemg_drake.tasks.plan import TaskPlan
from hemg_drake.teleop.config import OperatorConfig
from hemg_drake.teleop.human_style import human_draw_count, human_draws, humanised
from hemg_drake.teleop.mapping import WorkspaceMapping
from hemg_drake.teleop.master import saturate_norm
from hemg_drake.teleop import visual as vis

# The hand's impedance and force limit are OperatorConfig's; these names are for the
# browser's virtual hand, which takes the same.
HAND_STIFFNESS = OperatorConfig().hand_stiffness  # N/m
HAND_DAMPING = OperatorConfig().hand_damping  # N s/m
MAX_HAND_FORCE = OperatorConfig().max_hand_force  # N

# The variability's draws are sampled once, at initialisation: the random sources' own
# sampling interval is longer than any run.
_DRAW_INTERVAL = 1e9  # s

# Resolved once: a template lookup per call would cost microseconds at 1 kHz.
_DOUBLE_CONTEXT = Context_[float]


def hand_impedance_force(p_target, v_target, p_MS, v_MS, *, stiffness, damping, max_force):
    """The hand's force on the stylus, an impedance towards a target (eq. 19's F_h):
    F_h = sat(K_h (p_target - p_MS) + D_h (v_target - v_MS), max_force), saturated in norm.

    Parameters
    ----------
    p_target, v_target : 3 scalars each, m and m/s, where the hand heads for, in M.
    p_MS, v_MS : 3 scalars each (floats or AutoDiffXd), m and m/s, the stylus tip in M.
    stiffness, damping : float, K_h (N/m) and D_h (N s/m).
    max_force : float, N.

    Returns
    -------
    list of 3 scalars, N, in M. Plain Python arithmetic: this runs at the master's 1 kHz.
    """
    force = [
        stiffness * (pt - p) + damping * (vt - v)
        for pt, p, vt, v in zip(p_target, p_MS, v_target, v_MS)
    ]
    return saturate_norm(force, max_force)


def _checked(config):
    """OperatorConfig's model settings as checked floats (ValueError naming the field)."""
    if not isinstance(config, OperatorConfig):
        raise ValueError(f"config must be an OperatorConfig, got {type(config).__name__}")
    values = {}
    for name in ("hand_stiffness", "hand_damping", "max_hand_force", "co_contraction_gain",
                 "timing_std", "effort_std"):  # fmt: skip
        values[name] = as_scalar(name, getattr(config, name), strict=False)
    for name in ("activation_time_constant", "period"):
        values[name] = as_scalar(name, getattr(config, name))
    for name in ("rest", "free", "forceful"):
        level = as_scalar(f"{name}_activation", getattr(config, f"{name}_activation"),
                          strict=False)  # fmt: skip
        if level > 1.0:
            raise ValueError(f"{name}_activation must be in [0, 1], got {level}")
        values[name] = level
    return values


@TemplateSystem.define("OperatorLaw_", T_list=[float, AutoDiffXd])
def OperatorLaw_(T):
    class Impl(LeafSystem_[T]):
        """The operator's hand and muscle laws inside :class:`SimulatedOperator` (see there).

        .. pydrake_system::

            name: OperatorLaw
            input_ports:
            - p_MS
            - v_MS
            - feedback_force
            - normals
            - uniforms
            - human (style "human" only)
            output_ports:
            - hand_force
            - activation

        ``normals`` and ``uniforms`` are the draws of the plan's variability
        (:meth:`TaskPlan.perturbed_by`), read once by an initialisation event into the
        abstract state: the perturbed plan in W and in M (before initialisation: the plan
        of zero draws, the unperturbed one). With ``config.style`` "human", ``human`` holds
        the uniform draws of the human-like timing (:func:`~hemg_drake.teleop.human_style.
        humanised`), applied after the perturbation. Double and AutoDiffXd (for Clone; the plan is
        a function of time only, so the hand force is differentiable in p_MS, v_MS).
        """

        def _construct(
            self, *, plan, mapping, config, video_delay=0.0, command_delay=0.0,
            sheet_normal_W=None, converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            if not isinstance(plan, TaskPlan):
                raise ValueError(f"plan must be a TaskPlan, got {type(plan).__name__}")
            if not isinstance(mapping, WorkspaceMapping):
                raise ValueError(
                    f"mapping must be a WorkspaceMapping, got {type(mapping).__name__}"
                )
            self._plan, self._mapping, self._config = plan, mapping, config
            self._video_delay = float(video_delay)
            self._command_delay = float(command_delay)
            self._sheet_normal_W = sheet_normal_W
            # The sheet's normal in M: pen-down segments are seen on the sheet (visual.py).
            self._normal_M = None
            if sheet_normal_W is not None:
                n_W = as_vector("sheet_normal_W", sheet_normal_W, 3)
                length = float(np.linalg.norm(n_W))
                if length < 1e-9:
                    raise ValueError(f"sheet_normal_W must not be zero, got {n_W.tolist()}")
                self._normal_M = mapping.R_WM.inverse().multiply(n_W / length)
            values = _checked(config)
            self._values = values
            self._path_std = list(config.path_std)
            # Exact discretisation of a' = (a* - a) / tau with a* held over the period.
            self._decay = math.exp(-values["period"] / values["activation_time_constant"])
            n_normals, n_uniforms = plan.perturbation_sizes()
            self._p_MS_input = self.DeclareVectorInputPort("p_MS", 3)
            self._v_MS_input = self.DeclareVectorInputPort("v_MS", 3)
            self._feedback_force_input = self.DeclareVectorInputPort("feedback_force", 3)
            self._normals_input = self.DeclareVectorInputPort("normals", n_normals)
            self._uniforms_input = self.DeclareVectorInputPort("uniforms", n_uniforms)
            self._human_input = None
            human = None
            if config.style == "human":
                human = np.full(human_draw_count(plan), 0.5)
                self._human_input = self.DeclareVectorInputPort("human", human.size)
            self._visual = config.visual if config.visual.enabled else None
            draws = np.full(vis.DRAW_COUNT, 0.5)
            if self._visual is not None:
                # What the operator sees: the tool point in W, delayed by the channel's
                # slave-to-master delay and the reaction time. A shift register in this
                # system's state, not Drake's DiscreteTimeDelay: that one's history starts at
                # zero, and the operator must see the tool where it starts (set at init).
                self._seen_input = self.DeclareVectorInputPort("p_WE_seen", 3)
                self._visual_draws_input = self.DeclareVectorInputPort("visual", vis.DRAW_COUNT)
                self._n_seen = vis.delay_samples(self._visual, self._video_delay, values["period"])
                self._visual_index = self.DeclareDiscreteState(vis.initial_state())
                self._seen_index = self.DeclareDiscreteState(np.zeros(3 * self._n_seen))
                # The efference copy: what was sent (clock, correction) over the loop's latency.
                self._sent_index, self._n_sent = None, 0
                if self._visual.efference_copy:
                    self._n_sent = vis.loop_samples(
                        self._visual, self._command_delay, self._video_delay, values["period"]
                    )
                    self._sent_index = self.DeclareDiscreteState(np.zeros(4 * self._n_sent))
            nominal = (*self._plans(np.zeros(n_normals), np.zeros(n_uniforms), human), draws)
            self._plans_index = self.DeclareAbstractState(AbstractValue.Make(nominal))
            self.DeclareInitializationUnrestrictedUpdateEvent(self._draw)
            self._activation_index = self.DeclareDiscreteState([values["rest"]])
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=values["period"], offset_sec=0.0, update=self._update
            )
            self.DeclareVectorOutputPort(
                "hand_force", 3, self._calc_hand_force,
                prerequisites_of_calc={
                    self.time_ticket(), self._p_MS_input.ticket(), self._v_MS_input.ticket(),
                    self.abstract_state_ticket(self._plans_index),
                    *([] if self._visual is None else [self.all_state_ticket()]),
                },
            )  # fmt: skip
            self.DeclareStateOutputPort("activation", self._activation_index)
            if self._visual is not None:
                self.DeclareStateOutputPort("visual_state", self._visual_index)

        def _construct_copy(self, other, converter=None):
            Impl._construct(
                self, plan=other._plan, mapping=other._mapping, config=other._config,
                video_delay=other._video_delay, command_delay=other._command_delay,
                sheet_normal_W=other._sheet_normal_W, converter=converter,
            )  # fmt: skip

        def _plans(self, normals, uniforms, human=None):
            """(plan in W, plan in M) perturbed by the draws (and humanised by ``human``)."""
            values = self._values
            plan = self._plan.perturbed_by(
                normals, uniforms, timing_std=values["timing_std"], path_std=self._path_std,
                effort_std=values["effort_std"],
            )  # fmt: skip
            if human is not None:
                plan = humanised(plan, human, self._config.human)
            # The plan mapped into M once (the map is affine), rather than every sample.
            return plan, plan.in_frame(self._mapping.slave_to_master(plan.points))

        def _draw(self, context, state):
            normals = self._normals_input.Eval(context)
            uniforms = self._uniforms_input.Eval(context)
            human = None if self._human_input is None else self._human_input.Eval(context)
            if not isinstance(context, _DOUBLE_CONTEXT):
                normals = np.array([x.value() for x in normals])
                uniforms = np.array([x.value() for x in uniforms])
                if human is not None:
                    human = np.array([x.value() for x in human])
            draws = np.full(vis.DRAW_COUNT, 0.5)
            if self._visual is not None:
                draws = _floats(self._visual_draws_input.Eval(context))
                # Before the first update the operator sees the tool where it starts.
                seen = _floats(self._seen_input.Eval(context))
                state.get_mutable_discrete_state(self._seen_index).SetFromVector(
                    np.tile(seen, self._n_seen)
                )
                start = _float(context.get_time())
                state.get_mutable_discrete_state(self._visual_index).SetFromVector(
                    vis.initial_state(start)
                )
                if self._sent_index is not None:  # before the start: at the start, uncorrected
                    state.get_mutable_discrete_state(self._sent_index).SetFromVector(
                        np.tile([start, 0.0, 0.0, 0.0], self._n_sent)
                    )
            plans = (*self._plans(normals, uniforms, human), draws)
            state.get_mutable_abstract_state(self._plans_index).set_value(plans)

        def plan(self, context):
            """The perturbed plan in W that this context's operator follows."""
            return context.get_abstract_state(self._plans_index).get_value()[0]

        def _input(self, context, name, port):
            values = port.Eval(context).tolist()
            if isinstance(context, _DOUBLE_CONTEXT) and not all_finite(values):
                raise ValueError(f"{name} must be finite, got {values}")
            return values

        def _calc_hand_force(self, context, output):
            p_MS = self._input(context, "p_MS", self._p_MS_input)
            v_MS = self._input(context, "v_MS", self._v_MS_input)
            plans = context.get_abstract_state(self._plans_index).get_value()
            plan_M = plans[1]
            t = _float(context.get_time())
            if self._visual is None:
                p_target, v_target = plan_M.position_velocity_floats(t)
            else:
                state = _floats(context.get_discrete_state(self._visual_index).value())
                aim = vis.visual_target(state, t, plan_M, plans[2], self._visual)
                if aim is None:  # let go: no force on the stylus
                    output.SetFromVector(np.zeros(3))
                    return
                p_target, v_target = aim
            values = self._values
            output.SetFromVector(np.array(hand_impedance_force(
                p_target, v_target, p_MS, v_MS, stiffness=values["hand_stiffness"],
                damping=values["hand_damping"], max_force=values["max_hand_force"],
            )))  # fmt: skip

        def activation_target(self, context, t, feedback_force):
            """a* = clip(a_rest + effort (a_level - a_rest) + g_cc |f_felt|, 0, 1); the
            visual operator's segment is its plan clock's, and it rests once it let go."""
            values = self._values
            plan = self.plan(context)
            rest = values["rest"]
            if self._visual is not None:
                state = context.get_discrete_state(self._visual_index).value()
                if _float(state[vis.GAVE_UP]):
                    return rest
                t = _float(state[vis.S])
            if plan.start_time <= t <= plan.end_time:
                segment = plan.segment(t)
                level = rest + segment.effort * (values[segment.kind] - rest)
            else:
                level = rest
            x, y, z = feedback_force
            squared = x * x + y * y + z * z
            norm = math.sqrt(squared) if isinstance(squared, float) else squared.sqrt()
            target = level + values["co_contraction_gain"] * norm
            return min(max(target, 0.0), 1.0)

        def _update(self, context, discrete_state):
            felt = self._input(context, "feedback_force", self._feedback_force_input)
            t = context.get_time()
            t = t if isinstance(t, float) else t.value()
            activation = context.get_discrete_state(self._activation_index).GetAtIndex(0)
            target = self.activation_target(context, t, felt)
            discrete_state.get_mutable_vector(self._activation_index).SetAtIndex(
                0, target + (activation - target) * self._decay
            )
            if self._visual is not None:
                self._update_visual(context, discrete_state)

        def _update_visual(self, context, discrete_state):
            """Shift what the operator sees by one period, then step the visual law."""
            seen = _floats(context.get_discrete_state(self._seen_index).value())
            now = _floats(self._input(context, "p_WE_seen", self._seen_input))
            discrete_state.get_mutable_vector(self._seen_index).SetFromVector(
                np.concatenate([seen[3:], now])
            )
            seen_M = self._mapping.slave_to_master(seen[:3])
            plan_M = context.get_abstract_state(self._plans_index).get_value()[1]
            state = _floats(context.get_discrete_state(self._visual_index).value())
            sent = None
            if self._sent_index is not None:  # the oldest sent, then remember this one's
                history = _floats(context.get_discrete_state(self._sent_index).value())
                sent = history[:4]
                discrete_state.get_mutable_vector(self._sent_index).SetFromVector(
                    np.concatenate([history[4:], state[vis.S:vis.C.stop]])
                )
            discrete_state.get_mutable_vector(self._visual_index).SetFromVector(
                vis.visual_step(
                    state, seen_M, plan_M, self._visual, self._values["period"], self._normal_M,
                    sent,
                )
            )

        def sheet_normal_M(self):
            """The drawing sheet's unit normal in M as the visual operator uses it, or None."""
            return None if self._normal_M is None else np.array(self._normal_M)

        def visual_state(self, context):
            """The visual operator's state (:mod:`~hemg_drake.teleop.visual`), floats."""
            return _floats(context.get_discrete_state(self._visual_index).value())

    return Impl


OperatorLaw = OperatorLaw_[None]


def _float(x):
    return x if isinstance(x, float) else float(x.value())


def _floats(values):
    """A vector of floats or AutoDiffXd as floats (the visual law runs on values: what
    the operator sees is not differentiated through)."""
    array = np.asarray(values)
    if array.dtype == object:
        return np.array([_float(x) for x in array])
    return np.array(array, dtype=float)


class SimulatedOperator(Diagram):
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

    Hand: an impedance towards the plan mapped into the master frame M (eq. 19's F_h),
    F_h = K_h (p_MSplan(t) - p_MS) + D_h (v_MSplan(t) - v_MS), saturated in norm at
    ``config.max_hand_force`` (:func:`hand_impedance_force`). Muscle: a first-order
    activation a towards a* = clip(a_rest + effort (a_level - a_rest) + g_cc |f_felt|, 0, 1),
    a_level the free or forceful level of the plan's current segment (a_rest before and
    after the plan), effort the segment's effort scale, g_cc |f_felt| the co-contraction
    with which a human stiffens the arm against a felt force.

    Ports: ``p_MS`` (3, m), ``v_MS`` (3, m/s) the stylus tip in M; ``feedback_force``
    (3, N, in M) the force the hand feels from the device motors; ``hand_force`` (3, N, in
    M) for the HapticMaster's ``hand_force``; ``activation`` (1, in [0, 1]) for the
    synthetic EMG source.

    Timing: ``hand_force`` is a direct feedthrough of ``p_MS``, ``v_MS`` and the time (not
    of ``feedback_force``); the activation is discrete state, updated every
    ``config.period`` (5 ms) by the exact discretisation of the first-order muscle lag,
    from the rest level. NaN inputs raise ValueError.

    With ``config.visual.enabled`` the operator acts on what it sees
    (:mod:`~hemg_drake.teleop.visual`): an input ``p_WE_seen`` (3, m, in W) takes the slave's
    tool point; the law delays it by ``video_delay`` (s, the channel's slave-to-master delay)
    plus the reaction time, and the hand heads for the plan at its own clock (held at a
    waypoint until seen reached) plus the seen error's integral and a tremor; a fourth
    RandomSource (``visual``) holds the tremor's draws.

    Variability in the Context: the operator follows ``plan.perturbed_by(draws)``
    (timing, path offset, effort; spreads ``config.timing_std``, ``path_std``,
    ``effort_std``), the draws held by two Drake ``RandomSource`` systems (standard normal
    and uniform) and read at initialisation. With ``config.style`` "human" a third
    (uniform, ``human``) holds the human-like timing's draws
    (:mod:`~hemg_drake.teleop.human_style`: per-phase tempo, pauses, overshoot then
    correction, idle start). So one built diagram runs many seeds:
    ``diagram.SetRandomContext(context, RandomGenerator(seed))`` (as
    ``MonteCarloSimulation`` does) draws a new plan, and :meth:`set_seed` puts the draws of
    ``plan.perturbed(seed)`` (numpy's) in a context instead. Both before
    ``Simulator.Initialize``. Start the HapticMaster at the plan's first point mapped into
    M to avoid an initial jerk, and keep the mapped plan inside the master's workspace.

    Parameters
    ----------
    plan : TaskPlan
        The task's nominal plan (world frame).
    mapping : WorkspaceMapping
        Used backwards, to find where the stylus must be for the slave to be on the plan.
    config : OperatorConfig
        Hand impedance (N/m, N s/m) and force limit (N), activation levels, co-contraction
        gain (1/N), time constant (s), period (s), and the variability's spreads.
    video_delay : float
        The channel's slave-to-master delay (s) through which the visual operator sees.
    command_delay : float
        The channel's master-to-slave delay (s): with ``config.visual.efference_copy`` the
        operator knows its loop's latency (command delay + video delay + reaction time).
    sheet_normal_W : 3 floats, optional
        The drawing sheet's normal in W: the visual operator sees pen-down segments on the
        sheet (their depth it feels, not sees).
    """

    def __init__(
        self, *, plan, mapping, config=OperatorConfig(), video_delay=0.0, command_delay=0.0,
        sheet_normal_W=None,
    ):
        Diagram.__init__(self)
        builder = DiagramBuilder()
        law = builder.AddNamedSystem("law", OperatorLaw(
            plan=plan, mapping=mapping, config=config, video_delay=video_delay,
            command_delay=command_delay, sheet_normal_W=sheet_normal_W,
        ))  # fmt: skip
        self._law = law
        self.plan_nominal = plan
        n_normals, n_uniforms = plan.perturbation_sizes()
        normals = builder.AddNamedSystem(
            "normals", RandomSource(RandomDistribution.kGaussian, n_normals, _DRAW_INTERVAL)
        )
        uniforms = builder.AddNamedSystem(
            "uniforms", RandomSource(RandomDistribution.kUniform, n_uniforms, _DRAW_INTERVAL)
        )
        self._sources = (normals, uniforms)
        if config.style == "human":
            human = builder.AddNamedSystem("human", RandomSource(
                RandomDistribution.kUniform, human_draw_count(plan), _DRAW_INTERVAL
            ))  # fmt: skip
            builder.Connect(human.get_output_port(), law.GetInputPort("human"))
        if config.visual.enabled:
            visual = builder.AddNamedSystem("visual", RandomSource(
                RandomDistribution.kUniform, vis.DRAW_COUNT, _DRAW_INTERVAL
            ))  # fmt: skip
            builder.Connect(visual.get_output_port(), law.GetInputPort("visual"))
            builder.ExportInput(law.GetInputPort("p_WE_seen"), "p_WE_seen")
            builder.ExportOutput(law.GetOutputPort("visual_state"), "visual_state")
        builder.Connect(normals.get_output_port(), law.GetInputPort("normals"))
        builder.Connect(uniforms.get_output_port(), law.GetInputPort("uniforms"))
        for name in ("p_MS", "v_MS", "feedback_force"):
            builder.ExportInput(law.GetInputPort(name), name)
        for name in ("hand_force", "activation"):
            builder.ExportOutput(law.GetOutputPort(name), name)
        builder.BuildInto(self)

    def set_seed(self, context, seed):
        """Draw the variability of ``plan.perturbed(seed)`` into ``context`` (this diagram's
        context, before ``Simulator.Initialize``): the same seed gives main's plan."""
        set_operator_seed(self, context, self.plan_nominal, seed)

    def plan(self, context):
        """The perturbed plan in W that the operator follows in ``context`` (initialised)."""
        return self._law.plan(self.GetSubsystemContext(self._law, context))

    def sheet_normal_M(self):
        """The drawing sheet's unit normal in M (pen-down segments are seen on it), or None."""
        return self._law.sheet_normal_M()

    def visual_state(self, context):
        """With ``config.visual.enabled``: [s, c (3), waited, settled, gave up]
        (:mod:`~hemg_drake.teleop.visual`) in ``context`` (this diagram's)."""
        return self._law.visual_state(self.GetSubsystemContext(self._law, context))


def set_operator_seed(operator, context, plan, seed):
    """Draw the variability of ``plan.perturbed(seed)`` into ``context``, the context of
    ``operator``: a :class:`SimulatedOperator` or a ``Clone()`` of one, which Drake returns
    as a plain Diagram (the same subsystems, without this class's methods).

    Parameters
    ----------
    operator : Diagram with the subsystems ``normals`` and ``uniforms`` (RandomSources), and
        ``human`` with the human style.
    context : its Context (not the root's), before ``Simulator.Initialize``.
    plan : TaskPlan, the nominal plan the operator was built with.
    seed : int
    """
    for name, draws in zip(("normals", "uniforms"), plan.perturbation_draws(seed)):
        source = operator.GetSubsystemByName(name)
        operator.GetMutableSubsystemContext(source, context).SetDiscreteState(draws)
    if operator.HasSubsystemNamed("human"):  # the human style's draws, their own stream
        source = operator.GetSubsystemByName("human")
        operator.GetMutableSubsystemContext(source, context).SetDiscreteState(
            human_draws(plan, seed)
        )
    if operator.HasSubsystemNamed("visual"):  # the visual operator's tremor, its own stream
        source = operator.GetSubsystemByName("visual")
        operator.GetMutableSubsystemContext(source, context).SetDiscreteState(
            vis.visual_draws(seed)
        )
