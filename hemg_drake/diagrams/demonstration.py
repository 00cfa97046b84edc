"""The teleoperated demonstration diagram (the paper's learning phase) and one recorded run.

Signal flow (each box a LeafSystem of this package, named as in the diagram)::

    operator --hand_force--> master --p_MS, v_MS--> workspace_map --p_WE_desired--> clik
    clik --q_desired, v_desired--> pd --torque--> plant (arm + task scene)
    operator --activation--> emg_source --emg--> envelope --> variable_gain --gain-->
        gain_hold --> pd
    scene's interaction force f_WE --> force_feedback --motor_force--> master, operator
    logger (every log_period): p_WE, v_WE, p_MS, envelope, activation, gain, f_WE

:func:`build_demonstration_diagram` builds it from a :class:`~hemg_drake.scenario.Scenario`
and a seed; :func:`run_demonstration` simulates it and returns the logged
:class:`~hemg_drake.learning.demos.Demonstration`, optionally with an HTML replay;
:func:`record_demonstrations` runs the scenario's C demonstrations into a folder (what
``hemg-drake demonstrate`` does).
"""

import dataclasses as dc
import time
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from hemg_drake._validate import as_seed
from hemg_drake.diagrams.slave import add_logger, add_slave, build_with_viewers, split_log
from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.chain import add_emg_gain_chain
from hemg_drake.emg.sources import MYO_RATE, SyntheticEmgSource, synthesize_emg
from hemg_drake.learning.demos import FIELD_WIDTHS, Demonstration, save_dataset
from hemg_drake.robots.baxter import FLOOR_Z
from hemg_drake.teleop.feedback import ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMap, WorkspaceMapping
from hemg_drake.teleop.master import HapticMaster
from hemg_drake.teleop.operator import SimulatedOperator
from hemg_drake.viz.figures import plot_demonstrations, save_figure
from hemg_drake.viz.ink import add_ink_to_recording, in_contact
from hemg_drake.viz.recording import ReplayRecorder

# Logged signals after time, in the order of the logger's input vector.
LOGGED_FIELDS = tuple(name for name in FIELD_WIDTHS if name != "time")


class SampleHold(LeafSystem):
    """Samples its input periodically and holds it, starting from a given value.

    .. pydrake_system::

        name: SampleHold
        input_ports:
        - u
        output_ports:
        - y

    ``y`` (same size as ``initial``, same units as ``u``) is ``initial`` until the first
    sample at ``offset`` (s), then the input sampled every ``period`` (s). Drake's
    ``ZeroOrderHold`` does the same but starts at zero, which is no valid gain.

    Why here: Drake recomputes a stateless system's output whenever the time changes, so
    without the hold the gain chain would be evaluated at every 1 ms plant step although
    the sEMG envelope only changes at 200 Hz.
    """

    def __init__(self, *, initial, period, offset):
        LeafSystem.__init__(self)
        initial = np.atleast_1d(np.asarray(initial, dtype=float))
        self.u_input = self.DeclareVectorInputPort("u", len(initial))
        index = self.DeclareDiscreteState(initial)
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=period, offset_sec=offset, update=self._update
        )
        self.y_output = self.DeclareStateOutputPort("y", index)

    def _update(self, context, discrete_state):
        discrete_state.set_value(self.u_input.Eval(context))


@dc.dataclass(frozen=True)
class DemonstrationDiagram:
    """A built demonstration diagram and handles into it.

    Attributes
    ----------
    diagram : Diagram
        Subsystems by name: ``plant``, ``scene_graph``, ``operator``, ``master``,
        ``workspace_map``, ``clik``, ``pd``, ``emg_source``, ``envelope``,
        ``variable_gain``, ``gain_hold``, ``force_feedback``, ``tool_point``,
        ``log_mux``, ``logger``, and the scene's own systems (its force sensor gives
        ``f_WE``) or ``no_contact`` (zero force) in free space.
    plant : MultibodyPlant
    arm : BaxterArm
    plan : TaskPlan
        The seeded operator's plan (the task plan perturbed by the seed).
    mapping : WorkspaceMapping
    scene : object or None
        What the task's scene builder returned; None in free space.
    logger : VectorLogSink
        Logs ``LOGGED_FIELDS`` (15 numbers) every ``scenario.log_period``.
    """

    diagram: object
    plant: object
    arm: object
    plan: object
    mapping: WorkspaceMapping
    scene: object
    logger: object


def workspace_mapping(scenario):
    """The scenario's :class:`WorkspaceMapping`."""
    return WorkspaceMapping(
        scale=scenario.mapping.scale, R_WM=scenario.R_WM(), p_WMo=scenario.mapping.offset
    )


def operator_plan(scenario, seed):
    """The plan the seeded operator follows: the task plan perturbed by ``seed``."""
    config = scenario.operator
    return scenario.task_plan().perturbed(
        seed,
        timing_std=config.timing_std,
        path_std=config.path_std,
        effort_std=config.effort_std,
    )


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


def build_demonstration_diagram(scenario, *, seed, meshcat=None, recorder=None, scene=True):
    """Build the teleoperated demonstration diagram for one seeded demonstration.

    Parameters
    ----------
    scenario : Scenario
    seed : int
        Seeds the operator's variability (``plan.perturbed``) and the sEMG noise.
    meshcat : Meshcat, optional
        Live view: a ``MeshcatVisualizer`` of the scene graph is added.
    recorder : ReplayRecorder, optional
        Attached to the scene graph, to record an HTML replay.
    scene : bool
        False leaves out the task's scene: the arm in free space, no contact force.

    Returns
    -------
    DemonstrationDiagram
    """
    seed = as_seed(seed)
    operator_config = scenario.operator
    task_plan = scenario.task_plan()
    plan = operator_plan(scenario, seed)
    mapping = workspace_mapping(scenario)
    # Arm and stylus start at rest where the task is set up (the unperturbed plan's first
    # point, e.g. the pin's ring); the operator's own plan varies from there.
    p_MS_initial = mapping.slave_to_master(task_plan.points[0])

    builder = DiagramBuilder()
    slave = add_slave(builder, scenario, start=task_plan.points[0], scene=scene)
    plant, scene_graph, arm, task_scene = slave.plant, slave.scene_graph, slave.arm, slave.scene
    tool_point = slave.tool_point

    def add(name, system):
        return builder.AddNamedSystem(name, system)

    operator = add(
        "operator",
        SimulatedOperator(plan=plan, mapping=mapping, **operator_config.model_parameters()),
    )
    master_config = dc.asdict(scenario.master)
    master = add("master", HapticMaster(p_MS_initial=p_MS_initial, **master_config))
    workspace_map = add(
        "workspace_map",
        WorkspaceMap(
            mapping=mapping, delay_steps=scenario.mapping.delay_steps, p_MS_initial=p_MS_initial
        ),
    )
    emg_source = add("emg_source", SyntheticEmgSource(seed=seed))
    envelope, variable_gain = add_emg_gain_chain(
        builder,
        emg_source.get_emg_output_port(),
        calibration=emg_calibration(scenario),
        A_emg=scenario.emg.A_emg,
        k_min=scenario.emg.k_min,
        k_max=scenario.emg.k_max,
    )
    envelope.set_name("envelope")
    variable_gain.set_name("variable_gain")
    feedback_config = dc.asdict(scenario.feedback)
    force_feedback = add("force_feedback", ForceFeedback(mapping=mapping, **feedback_config))

    connect = builder.Connect
    connect(operator.GetOutputPort("hand_force"), master.GetInputPort("hand_force"))
    connect(operator.GetOutputPort("activation"), emg_source.get_activation_input_port())
    for name in ("p_MS", "v_MS"):
        connect(master.GetOutputPort(name), operator.GetInputPort(name))
        connect(master.GetOutputPort(name), workspace_map.GetInputPort(name))
    connect(workspace_map.GetOutputPort("p_WE_desired"), slave.p_WE_desired_input)
    # The envelope updates half a MYO period after each sample; the hold reads it a plant
    # step later, so the PD's gain lags the envelope by one plant step.
    gain_hold = add(
        "gain_hold",
        SampleHold(
            initial=[scenario.emg.k_min],
            period=1.0 / MYO_RATE,
            offset=0.5 / MYO_RATE + scenario.plant.time_step,
        ),
    )
    connect(variable_gain.get_gain_output_port(), gain_hold.u_input)
    connect(gain_hold.y_output, slave.gain_input)

    f_WE = slave.f_WE_output
    if scenario.feedback.mode == "force":
        connect(f_WE, force_feedback.GetInputPort("f_WE"))
    else:
        connect(tool_point.p_WE_output, force_feedback.GetInputPort("p_WE"))
        connect(tool_point.v_WE_output, force_feedback.GetInputPort("v_WE"))
        for name in ("p_MS", "v_MS"):
            connect(master.GetOutputPort(name), force_feedback.GetInputPort(name))
    motor_force = force_feedback.GetOutputPort("motor_force")
    connect(motor_force, master.GetInputPort("motor_force"))
    connect(motor_force, operator.GetInputPort("feedback_force"))

    sources = {
        "p_WE": tool_point.p_WE_output,
        "v_WE": tool_point.v_WE_output,
        "p_MS": master.GetOutputPort("p_MS"),
        "envelope": envelope.get_envelope_output_port(),
        "activation": variable_gain.get_activation_output_port(),
        "gain": gain_hold.y_output,
        "f_WE": f_WE,
    }
    ordered = {name: sources[name] for name in LOGGED_FIELDS}
    logger = add_logger(builder, ordered, scenario.log_period)
    diagram = build_with_viewers(
        builder, scene_graph, "demonstration", meshcat=meshcat, recorder=recorder
    )
    return DemonstrationDiagram(diagram, plant, arm, plan, mapping, task_scene, logger)


def demonstration_from_log(log, seed):
    """The :class:`Demonstration` held by the logger's log (a ``VectorLog``)."""
    blocks = split_log(log, {name: FIELD_WIDTHS[name] for name in LOGGED_FIELDS})
    fields = {name: block[:, 0] if block.shape[1] == 1 else block for name, block in blocks.items()}
    return Demonstration(seed=seed, time=log.sample_times(), **fields)


def run_demonstration(scenario, seed, *, replay_path=None, scene=True):
    """Simulate one demonstration of ``scenario.duration`` seconds.

    Parameters
    ----------
    scenario : Scenario
    seed : int
    replay_path : path-like, optional
        Write a self-contained HTML replay there (with the ink for drawing).
    scene : bool
        False: free space (see :func:`build_demonstration_diagram`).

    Returns
    -------
    Demonstration
    """
    recorder = None if replay_path is None else ReplayRecorder(floor_z=FLOOR_Z)
    built = build_demonstration_diagram(scenario, seed=seed, recorder=recorder, scene=scene)
    simulator = Simulator(built.diagram)
    simulator.Initialize()
    if recorder is not None:
        recorder.start()
    simulator.AdvanceTo(scenario.duration)
    context = simulator.get_context()
    demo = demonstration_from_log(built.logger.FindLog(context), seed)
    if recorder is not None:
        if scenario.task == "drawing" and built.scene is not None:
            # The ink is drawn into the open recording, just above the sheet.
            add_ink_to_recording(
                recorder.meshcat,
                demo.time,
                demo.p_WE,
                in_contact(demo.f_WE),
                height=built.scene.paper_height + 5e-4,
            )
        recorder.stop_and_export(replay_path)
    return demo


def record_demonstrations(scenario, out_dir, *, replays=True, progress=None):
    """Run the scenario's C demonstrations and write them to ``out_dir``.

    Writes ``dataset.npz`` (:func:`~hemg_drake.learning.demos.save_dataset`, with the
    scenario's YAML, task, N and log period in the metadata), ``replay_<c>.html`` for
    c = 1 .. C when ``replays``, and ``demonstrations.png`` (Fig. 8 (a)-(b) or Fig. 10).
    Every file is written atomically, so existing files are replaced whole or not at all.

    Parameters
    ----------
    scenario : Scenario
    out_dir : path-like, created if missing.
    replays : bool
    progress : callable, optional
        Called with one line of text per finished demonstration.

    Returns
    -------
    list of Path, the files written (dataset first).
    """
    out_dir = Path(out_dir)
    demos, written = [], []
    for c, seed in enumerate(scenario.seeds(), start=1):
        replay = out_dir / f"replay_{c}.html" if replays else None
        start = time.perf_counter()
        demos.append(run_demonstration(scenario, seed, replay_path=replay))
        if replay is not None:
            written.append(replay)
        if progress is not None:
            plan_end = operator_plan(scenario, seed).end_time
            progress(
                f"demonstration {c}/{scenario.num_demonstrations} (seed {seed}): "
                f"{scenario.duration:g} s simulated in {time.perf_counter() - start:.1f} s"
                + (f", replay {replay}" if replay else "")
                + (
                    f"; cut short: the operator's plan ends at {plan_end:.2f} s"
                    if plan_end > scenario.duration
                    else ""
                )
            )
    dataset = out_dir / "dataset.npz"
    metadata = dict(
        scenario=scenario.to_yaml(),
        task=scenario.task,
        num_states=scenario.num_states,
        log_period=scenario.log_period,
    )
    save_dataset(dataset, demos, metadata)
    figure = out_dir / "demonstrations.png"
    save_figure(plot_demonstrations(demos, task=scenario.task), figure)
    return [dataset, *written, figure]
