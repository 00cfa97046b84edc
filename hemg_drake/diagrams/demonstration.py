"""The teleoperated demonstration diagram (the paper's learning phase) and one recorded run.

Signal flow (each box a LeafSystem of this package, named as in the diagram)::

    operator --hand_force--> master --p_MS, v_MS--> workspace_map --p_WE_desired--> station
    operator --activation--> emg_source --emg--> envelope --> variable_gain --gain--> station
    station's interaction force f_WE --> force_feedback --motor_force--> master, operator
    logger (every log_period): p_WE, v_WE, p_MS, p_WE_desired, envelope, activation, gain, f_WE,
        the arm's joint positions q and the tool's rotation R_WE
    emg_logger (200 Hz): the raw sEMG and the operator's muscle activation

The station (:func:`~hemg_drake.diagrams.station.make_slave_station`) holds the plant, the
scene, the CLIK (eq. 21) and the variable-gain PD (eq. 20). The gain goes to the PD
unsampled: ``VariableGain`` declares its prerequisites, so Drake recomputes it only when the
200 Hz envelope changes (201 evaluations per simulated second, measured), and a hold would
only delay it.

:func:`build_demonstration_diagram` builds it from a :class:`~hemg_drake.scenario.Scenario`
and a seed (and only builds); :func:`run_demonstration` simulates a built diagram and
returns the logged :class:`~hemg_drake.learning.demos.Demonstration`. Built with a
``visualization``, the station is shown in its Meshcat; the application records the replay
(:mod:`hemg_drake.viz.recording`).

Seeds live in the Context, not in the diagram: the seed of a demonstration draws the
operator's variability (the perturbed plan) and the armband's noise into a fresh context
(:func:`seed_context`), so one built diagram runs every demonstration of a scenario, its
clones run in parallel, and Drake's ``MonteCarloSimulation`` can drive it.
"""

import dataclasses as dc

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Demultiplexer

from hemg_drake._validate import as_seed
from hemg_drake.diagrams.built import StationDiagram, make_simulator
from hemg_drake.diagrams.log import add_logger, split_log
from hemg_drake.diagrams.station import make_slave_station
from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.chain import add_emg_gain_chain
from hemg_drake.emg.sources import MYO_PERIOD, MYO_RATE, make_synthetic_emg_source, synthesize_emg
from hemg_drake.learning.demos import ARM_FIELD_SHAPES, FIELD_WIDTHS, Demonstration
from hemg_drake.teleop.feedback import ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMap
from hemg_drake.teleop.master import HapticMaster
from hemg_drake.teleop.operator import SimulatedOperator, set_operator_seed

# Logged signals after time, in the order of the logger's input vector, and their widths.
LOGGED_FIELDS = (*(name for name in FIELD_WIDTHS if name != "time"), *ARM_FIELD_SHAPES)
LOGGED_WIDTHS = {
    **FIELD_WIDTHS, **{name: int(np.prod(shape)) for name, shape in ARM_FIELD_SHAPES.items()}
}


@dc.dataclass(frozen=True, eq=False)
class DemonstrationDiagram(StationDiagram):
    """A built demonstration diagram and handles into it.

    Attributes
    ----------
    diagram : Diagram
        Subsystems by name: ``station`` (the slave), ``operator``, ``master``,
        ``workspace_map``, ``emg_source``, ``envelope``, ``variable_gain``,
        ``force_feedback``, ``arm_positions`` (q out of the station's arm_state),
        ``logger`` and ``emg_logger`` (and their muxes).
    station : SlaveStation
    scenario : Scenario
    mapping : WorkspaceMapping
    logger : VectorLogSink, ``LOGGED_FIELDS`` every ``scenario.log_period``.
    emg_logger : VectorLogSink, [sEMG (8), muscle activation (1)] every 5 ms.
    assist_logger : VectorLogSink or None
        With ``assist.mode`` other than none: the assist's signals
        (:data:`~hemg_drake.diagrams.assist.ASSIST_LOGGED`) every ``scenario.log_period``.
    interaction_logger : VectorLogSink
        The operator's hand force and the stylus velocity (the operator's effort), the
        passivity observer's energy (with a delay or tdpa) and the visual operator's state
        (``operator.visual``), every ``scenario.log_period``; ``interaction_widths``: their
        names and widths, in order.
    """

    scenario: object
    mapping: object
    logger: object
    emg_logger: object
    assist_logger: object = None
    interaction_logger: object = None
    interaction_widths: dict = None


def operator_plan(scenario, seed):
    """The plan the seeded operator follows: the task plan perturbed by ``seed`` (and, with
    ``operator.style`` "human", humanised by the seed's human draws)."""
    from hemg_drake.teleop.human_style import human_draws, humanised

    config = scenario.operator
    nominal = scenario.task_plan()
    plan = nominal.perturbed(
        seed,
        timing_std=config.timing_std,
        path_std=config.path_std,
        effort_std=config.effort_std,
    )
    if config.style == "human":
        plan = humanised(plan, human_draws(nominal, seed), config.human)
    return plan


def emg_calibration(scenario):
    """Calibration of the synthetic armband: rest and maximum-contraction recordings.

    Both recordings last ``scenario.emg.calibration_duration`` and are seeded from
    ``scenario.seed`` (rest: seed, MVC: seed + 1), not per demonstration: one calibration
    per session, as a person would do once before demonstrating.
    """
    # At least one RMS window long: load_scenario checks it.
    samples = int(round(scenario.emg.calibration_duration * MYO_RATE))
    return EmgCalibration.from_recordings(
        synthesize_emg(np.zeros(samples), scenario.seed),
        synthesize_emg(np.ones(samples), scenario.seed + 1),
        scenario.emg.window,
        per_channel=scenario.emg.per_channel,
    )


def make_emg_source(scenario):
    """The raw sEMG source of ``scenario.emg.source``: the synthetic armband, or a
    live one (``LiveEmgSource``: a MYO through pyomyo, or a LibEMG streamer's shared memory).
    """
    source = scenario.emg.source
    if source == "synthetic":
        return make_synthetic_emg_source()
    if source == "myo":
        from hemg_drake.emg.sources import LiveEmgSource, open_myo_device

        return LiveEmgSource(device=open_myo_device())
    from hemg_drake.emg.libemg import libemg_emg_source

    return libemg_emg_source(tag=scenario.emg.libemg_tag)[0]


def build_demonstration_diagram(
    scenario, *, visualization=None, scene=True, operator_factory=None
):
    """Build the teleoperated demonstration diagram of a scenario (any seed: see
    :func:`seed_context`).

    Parameters
    ----------
    scenario : Scenario
    visualization : Visualization, optional
        Show the station in its (loopback) Meshcat with ``scenario.visualization``.
    scene : bool
        False leaves out the task's scene: the arm in free space, no contact force.
    operator_factory : callable, optional
        Replaces the simulated operator (e.g. a person at the browser,
        :mod:`hemg_drake.teleop.browser`): called as ``operator_factory(scenario=,
        mapping=, p_MS_initial=)``, it returns a System with the
        SimulatedOperator's ports (inputs ``p_MS``, ``v_MS``, ``feedback_force``; outputs
        ``hand_force``, ``activation``), added as ``operator``.

    Returns
    -------
    DemonstrationDiagram
    """
    mapping = scenario.workspace_mapping()
    # Arm and stylus start at rest where the task is set up (the unperturbed plan's first
    # point, e.g. the pin's ring); the operator's own plan varies from there.
    start = scenario.task_plan().points[0]
    p_MS_initial = mapping.slave_to_master(start)

    builder = DiagramBuilder()
    station = make_slave_station(scenario, start=start, scene=scene, visualization=visualization)
    slave = builder.AddSystem(station.diagram)

    def add(name, system):
        return builder.AddNamedSystem(name, system)

    if operator_factory is None:
        operator_system = SimulatedOperator(
            plan=scenario.task_plan(), mapping=mapping, config=scenario.operator,
            # The visual operator sees the slave through the channel's slave-to-master half.
            video_delay=scenario.feedback.delay_steps * scenario.master.period,
            command_delay=scenario.mapping.delay_steps * scenario.master.period,
            sheet_normal_W=(
                scenario.X_WT().rotation().matrix()[:, 2] if scenario.task == "drawing" else None
            ),
        )
    else:
        operator_system = operator_factory(
            scenario=scenario, mapping=mapping, p_MS_initial=p_MS_initial
        )
    operator = add("operator", operator_system)
    master = add("master", HapticMaster(config=scenario.master, p_MS_initial=p_MS_initial))
    workspace_map = add(
        "workspace_map",
        WorkspaceMap(
            mapping=mapping,
            period=scenario.master.period,  # the channel's samples are the master's
            p_MS_initial=p_MS_initial,
            config=scenario.mapping,
        ),
    )
    emg_source = add("emg_source", make_emg_source(scenario))
    envelope, variable_gain = add_emg_gain_chain(
        builder,
        emg_source.GetOutputPort("emg"),
        config=scenario.emg,
        calibration=emg_calibration(scenario),
    )
    envelope.set_name("envelope")
    variable_gain.set_name("variable_gain")
    force_feedback = add(
        "force_feedback",
        ForceFeedback(mapping=mapping, period=scenario.master.period, config=scenario.feedback),
    )

    connect = builder.Connect
    connect(operator.GetOutputPort("hand_force"), master.GetInputPort("hand_force"))
    if emg_source.num_input_ports():  # the synthetic armband reads the operator's activation
        connect(operator.GetOutputPort("activation"), emg_source.GetInputPort("activation"))
    for name in ("p_MS", "v_MS"):
        connect(master.GetOutputPort(name), operator.GetInputPort(name))
        connect(master.GetOutputPort(name), workspace_map.GetInputPort(name))
    if operator.HasInputPort("p_WE_seen"):  # the visual operator watches the tool
        connect(slave.GetOutputPort("p_WE"), operator.GetInputPort("p_WE_seen"))
    p_WE_desired = workspace_map.GetOutputPort("p_WE_desired")
    connect(variable_gain.get_gain_output_port(), slave.GetInputPort("gain"))

    f_WE = slave.GetOutputPort("f_WE")
    reference, fed_back, assist_sources = p_WE_desired, f_WE, None
    if scenario.assist.mode != "none" or scenario.assist.gap_duration > 0:  # the assist, or
        # a lossy link without it (docs/shared_control.md)
        from hemg_drake.diagrams.assist import add_assist, assist_model

        reference, fed_back, assist_sources = add_assist(
            builder, scenario, model=assist_model(scenario), start=start,
            command=p_WE_desired, p_WE=slave.GetOutputPort("p_WE"), f_WE=f_WE,
            activation=variable_gain.get_activation_output_port(),
            enabled=operator.GetOutputPort("assist_on") if operator.HasOutputPort("assist_on")
            else None,
        )  # fmt: skip
    connect(reference, slave.GetInputPort("p_WE_desired"))
    if scenario.feedback.mode == "force":
        connect(fed_back, force_feedback.GetInputPort("f_WE"))
        if force_feedback.HasInputPort("v_MS"):  # the passivity controller reads the stylus
            connect(master.GetOutputPort("v_MS"), force_feedback.GetInputPort("v_MS"))
    else:
        connect(slave.GetOutputPort("p_WE"), force_feedback.GetInputPort("p_WE"))
        connect(slave.GetOutputPort("v_WE"), force_feedback.GetInputPort("v_WE"))
        for name in ("p_MS", "v_MS"):
            connect(master.GetOutputPort(name), force_feedback.GetInputPort(name))
    motor_force = force_feedback.GetOutputPort("motor_force")
    connect(motor_force, master.GetInputPort("motor_force"))
    connect(motor_force, operator.GetInputPort("feedback_force"))

    # The arm's [q; v] split by Drake's Demultiplexer: q is logged, v left unconnected.
    arm_positions = add("arm_positions", Demultiplexer([7, 7]))
    connect(slave.GetOutputPort("arm_state"), arm_positions.get_input_port())
    sources = {
        "p_WE": slave.GetOutputPort("p_WE"),
        "v_WE": slave.GetOutputPort("v_WE"),
        "p_MS": master.GetOutputPort("p_MS"),
        "p_WE_desired": p_WE_desired,
        "envelope": envelope.get_envelope_output_port(),
        "activation": variable_gain.get_activation_output_port(),
        "gain": variable_gain.get_gain_output_port(),
        "f_WE": f_WE,
        "q": arm_positions.get_output_port(0),
        "R_WE": slave.GetOutputPort("R_WE"),
    }
    logger = add_logger(builder, {name: sources[name] for name in LOGGED_FIELDS}, scenario.log_period)
    emg_sources = {
        "emg": emg_source.GetOutputPort("emg"),
        "muscle_activation": operator.GetOutputPort("activation"),
    }
    emg_logger = add_logger(builder, emg_sources, MYO_PERIOD, name="emg_logger")
    interaction_sources = {
        "hand_force": operator.GetOutputPort("hand_force"),
        "v_MS": master.GetOutputPort("v_MS"),
    }
    if force_feedback.HasOutputPort("energy"):
        interaction_sources["passivity_energy"] = force_feedback.GetOutputPort("energy")
    if operator.HasOutputPort("visual_state"):
        interaction_sources["visual_state"] = operator.GetOutputPort("visual_state")
    interaction_logger = add_logger(
        builder, interaction_sources, scenario.log_period, name="interaction_logger"
    )
    assist_logger = None
    if assist_sources is not None:
        assist_logger = add_logger(
            builder, assist_sources, scenario.log_period, name="assist_logger"
        )
    diagram = builder.Build()
    diagram.set_name("demonstration")
    return DemonstrationDiagram(
        diagram=diagram,
        station=station,
        scenario=scenario,
        mapping=mapping,
        logger=logger,
        emg_logger=emg_logger,
        assist_logger=assist_logger,
        interaction_logger=interaction_logger,
        interaction_widths={name: port.size() for name, port in interaction_sources.items()},
    )


def demonstration_from_logs(log, emg_log, seed):
    """The :class:`Demonstration` held by the two loggers' logs (``VectorLog``).

    A logger sees its ports before the updates at its own sample instants: row k + 1 of
    the sEMG log holds sample k (emitted at k / 200 s), and row k the muscle activation
    that the source read for it. The last activation row, whose sample is not logged, is
    dropped.
    """
    blocks = split_log(log, {name: LOGGED_WIDTHS[name] for name in LOGGED_FIELDS})
    fields = {name: block[:, 0] if block.shape[1] == 1 else block for name, block in blocks.items()}
    fields["R_WE"] = fields["R_WE"].reshape(-1, 3, 3)  # the station's rows, one after another
    emg_blocks = split_log(emg_log, {"emg": 8, "muscle_activation": 1})
    emg = emg_blocks["emg"][1:]
    return Demonstration(
        seed=seed,
        time=log.sample_times(),
        emg_time=np.arange(len(emg)) * MYO_PERIOD,
        emg=emg,
        muscle_activation=emg_blocks["muscle_activation"][:-1, 0],
        **fields,
    )


def seed_context(built, context, seed, *, diagram=None):
    """Draw demonstration ``seed`` into ``context``, a root context of ``diagram`` (default
    ``built.diagram``; or a ``Clone()`` of it), before ``Simulator.Initialize``: the
    armband's noise (its RandomSource, by ``SetRandomContext``) and the simulated operator's
    variability, so that it follows :func:`operator_plan` (scenario, seed). Another
    operator (``operator_factory``) keeps its own inputs."""
    seed = as_seed(seed)
    diagram = built.diagram if diagram is None else diagram
    # First: SetRandomContext also redraws the operator's variability at random.
    diagram.SetRandomContext(context, RandomGenerator(seed))
    operator = diagram.GetSubsystemByName("operator")
    if hasattr(operator, "HasSubsystemNamed") and operator.HasSubsystemNamed("normals"):
        own = operator.GetMyMutableContextFromRoot(context)
        set_operator_seed(operator, own, built.scenario.task_plan(), seed)


def initial_context(built, seed, *, diagram=None):
    """A root context of ``diagram`` (default ``built.diagram``; or a ``Clone()`` of it)
    ready to simulate demonstration ``seed``: the arm at rest at its start
    (``built.station.q0``) and the seed's draws (:func:`seed_context`).

    The start is set here rather than left to the plant's default positions because
    Drake's scalar conversion of a MultibodyPlant (which ``Clone()`` uses) does not carry
    the joints' default positions (measured on drake 1.51: a clone starts at q = 0).
    """
    diagram = built.diagram if diagram is None else diagram
    context = diagram.CreateDefaultContext()
    seed_context(built, context, seed, diagram=diagram)
    built.station.set_start(context, diagram.GetSubsystemByName("station"))
    return context


def run_demonstration(built, seed, *, duration=None):
    """:func:`run_demonstration_logged`'s demonstration alone."""
    return run_demonstration_logged(built, seed, duration=duration)[0]


def interaction_signals(built, context):
    """The run's signals beside the demonstration, name -> array (T, width): ``time`` and
    the interaction logger's (hand force, v_MS, ...), and with the assist
    ``assist.<name>`` (:data:`~hemg_drake.diagrams.assist.ASSIST_LOGGED`)."""
    log = built.interaction_logger.FindLog(context)
    signals = {"time": log.sample_times()[:, None]}
    signals.update(split_log(log, built.interaction_widths))
    if built.assist_logger is not None:
        from hemg_drake.diagrams.assist import ASSIST_LOGGED

        assist = split_log(built.assist_logger.FindLog(context), ASSIST_LOGGED)
        signals.update({f"assist.{name}": value for name, value in assist.items()})
    return signals


def run_demonstration_logged(built, seed, *, duration=None):
    """Simulate demonstration ``seed`` on a built diagram (a fresh context each call) and
    read its logs.

    Parameters
    ----------
    built : DemonstrationDiagram
    seed : int
        Draws the operator's variability and the sEMG noise (:func:`seed_context`).
    duration : float, optional
        Simulated seconds; default the scenario's ``duration``.

    Returns
    -------
    (Demonstration, dict): the demonstration and :func:`interaction_signals`.
    """
    simulator, duration = make_simulator(built, duration)
    simulator.reset_context(initial_context(built, seed))
    simulator.Initialize()
    simulator.AdvanceTo(duration)
    context = simulator.get_context()
    demo = demonstration_from_logs(
        built.logger.FindLog(context), built.emg_logger.FindLog(context), as_seed(seed)
    )
    return demo, interaction_signals(built, context)


def record_demonstration(scenario, seed, *, scene=True):
    """Build and run one demonstration: :func:`build_demonstration_diagram` then
    :func:`run_demonstration`. To run several seeds, build once and call
    :func:`run_demonstration` per seed."""
    built = build_demonstration_diagram(scenario, scene=scene)
    return run_demonstration(built, seed)
