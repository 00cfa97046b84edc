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
from pydrake.geometry import MeshcatVisualizer
from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, Multiplexer

from hemg_drake.control.clik import Clik
from hemg_drake.control.pd import VariableGainPd
from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.chain import add_emg_gain_chain
from hemg_drake.emg.sources import MYO_RATE, SyntheticEmgSource, synthesize_emg
from hemg_drake.learning.demos import FIELD_WIDTHS, Demonstration, save_dataset
from hemg_drake.robots.baxter import FLOOR_Z, add_baxter_arm
from hemg_drake.tasks.cotter_pin import add_cotter_pin_scene
from hemg_drake.tasks.drawing import add_drawing_scene
from hemg_drake.teleop.feedback import ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMap, WorkspaceMapping
from hemg_drake.teleop.master import HapticMaster
from hemg_drake.teleop.operator import SimulatedOperator
from hemg_drake.viz.figures import plot_demonstrations, save_figure
from hemg_drake.viz.ink import add_ink_to_recording, in_contact
from hemg_drake.viz.recording import ReplayRecorder

# Each task's scene: added to the plant before Finalize, its handle has force_output_port.
SCENE_BUILDERS = {"cotter_pin": add_cotter_pin_scene, "drawing": add_drawing_scene}
# Logged signals after time, in the order of the logger's input vector.
LOGGED_FIELDS = tuple(name for name in FIELD_WIDTHS if name != "time")


class ToolPointKinematics(LeafSystem):
    """Position and velocity of the arm's tool point E in the world, from the arm's state.

    .. pydrake_system::

        name: ToolPointKinematics
        input_ports:
        - state
        output_ports:
        - p_WE
        - v_WE

    ``state`` is the arm's [q; v] (14: rad, rad/s); ``p_WE`` (3, m) and ``v_WE`` (3, m/s)
    are the origin of ``frame_E`` (the tool frame) measured and expressed in W, by forward
    kinematics on the controller's own plant context: v_WE = J_WE(q) v.

    Timing: stateless, direct feedthrough; computed only when a consumer (the logger every
    log period, or the force feedback in ``position_error`` mode) evaluates it.
    """

    def __init__(self, *, plant, arm, frame_E=None):
        LeafSystem.__init__(self)
        self._plant = plant
        self._context = plant.CreateDefaultContext()
        self._model = arm.model_instance
        self._frame_E = arm.tool_frame if frame_E is None else frame_E
        all_velocities = np.arange(plant.num_velocities(), dtype=float)
        self._columns = plant.GetVelocitiesFromArray(self._model, all_velocities).astype(int)
        n = len(arm.joint_names)
        self._n = n
        self.state_input = self.DeclareVectorInputPort("state", 2 * n)
        self.p_WE_output = self.DeclareVectorOutputPort("p_WE", 3, self._calc_p_WE)
        self.v_WE_output = self.DeclareVectorOutputPort("v_WE", 3, self._calc_v_WE)

    def _set_positions(self, context):
        x = self.state_input.Eval(context)
        self._plant.SetPositions(self._context, self._model, x[: self._n])
        return x[self._n :]

    def _calc_p_WE(self, context, output):
        self._set_positions(context)
        output.SetFromVector(self._frame_E.CalcPoseInWorld(self._context).translation())

    def _calc_v_WE(self, context, output):
        v = self._set_positions(context)
        world = self._plant.world_frame()
        J_WE = self._plant.CalcJacobianTranslationalVelocity(
            self._context, JacobianWrtVariable.kV, self._frame_E, np.zeros(3), world, world
        )
        output.SetFromVector(J_WE[:, self._columns] @ v)


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


def emg_calibration(scenario):
    """Calibration of the synthetic armband: rest and maximum-contraction recordings.

    Both recordings last ``scenario.emg.calibration_duration`` and are seeded from
    ``scenario.seed`` (rest: seed, MVC: seed + 1), not per demonstration: one calibration
    per session, as a person would do once before demonstrating.
    """
    samples = int(round(scenario.emg.calibration_duration * MYO_RATE))
    if samples < scenario.emg.window:
        raise ValueError(
            f"emg.calibration_duration gives {samples} samples, fewer than the window "
            f"{scenario.emg.window}"
        )
    return EmgCalibration.from_recordings(
        synthesize_emg(np.zeros(samples), scenario.seed),
        synthesize_emg(np.ones(samples), scenario.seed + 1),
        scenario.emg.window,
        per_channel=scenario.emg.per_channel,
    )


def solve_arm_positions(plant, arm, p_WE, *, iterations=200, damping=0.01):
    """Arm configuration that puts the tool point at ``p_WE``, from the home configuration.

    Damped Newton steps on the tool point's translational Jacobian, kept inside the joint
    limits. Used to start a demonstration at rest on the plan's first point.

    Returns
    -------
    q : array, shape (7,), rad.

    Raises
    ------
    ValueError
        The point is not reached within 1 mm.
    """
    context = plant.CreateDefaultContext()
    world = plant.world_frame()
    all_velocities = np.arange(plant.num_velocities(), dtype=float)
    columns = plant.GetVelocitiesFromArray(arm.model_instance, all_velocities).astype(int)
    q = arm.home_positions.copy()
    for _ in range(iterations):
        plant.SetPositions(context, arm.model_instance, q)
        error = p_WE - arm.tool_frame.CalcPoseInWorld(context).translation()
        if np.linalg.norm(error) < 1e-6:
            break
        J = plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kV, arm.tool_frame, np.zeros(3), world, world
        )[:, columns]
        step = J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(3), error)
        q = np.clip(q + step, arm.position_lower, arm.position_upper)
    if np.linalg.norm(error) > 1e-3:
        raise ValueError(f"the plan's first point {p_WE.tolist()} is out of the arm's reach")
    return q


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
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    seed = int(seed)
    operator_config = scenario.operator
    task_plan = scenario.task_plan()
    plan = task_plan.perturbed(
        seed,
        timing_std=operator_config.timing_std,
        path_std=operator_config.path_std,
        effort_std=operator_config.effort_std,
    )
    mapping = workspace_mapping(scenario)
    # Arm and stylus start at rest where the task is set up (the unperturbed plan's first
    # point, e.g. the pin's ring); the operator's own plan varies from there.
    p_MS_initial = mapping.slave_to_master(task_plan.points[0])

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(scenario.plant, builder)
    arm = add_baxter_arm(plant)
    task_scene = SCENE_BUILDERS[scenario.task](plant, arm) if scene else None
    plant.Finalize()
    plant.SetDefaultPositions(
        arm.model_instance, solve_arm_positions(plant, arm, task_plan.points[0])
    )

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
    clik_config = scenario.clik
    clik = add(
        "clik",
        Clik(
            plant=plant,
            model_instance=arm.model_instance,
            frame_E=arm.tool_frame,
            gain=clik_config.gain,
            method=clik_config.method,
            damping=clik_config.damping,
            period=clik_config.period,
        ),
    )
    pd = add("pd", VariableGainPd(plant=plant, arm=arm))
    tool_point = add("tool_point", ToolPointKinematics(plant=plant, arm=arm))
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

    arm_state = plant.get_state_output_port(arm.model_instance)
    connect = builder.Connect
    connect(operator.GetOutputPort("hand_force"), master.GetInputPort("hand_force"))
    connect(operator.GetOutputPort("activation"), emg_source.get_activation_input_port())
    for name in ("p_MS", "v_MS"):
        connect(master.GetOutputPort(name), operator.GetInputPort(name))
        connect(master.GetOutputPort(name), workspace_map.GetInputPort(name))
    connect(workspace_map.GetOutputPort("p_WE_desired"), clik.GetInputPort("p_WE_desired"))
    connect(arm_state, clik.GetInputPort("state"))
    connect(arm_state, pd.state_input)
    connect(arm_state, tool_point.state_input)
    connect(clik.GetOutputPort("q_desired"), pd.q_desired_input)
    connect(clik.GetOutputPort("v_desired"), pd.v_desired_input)
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
    connect(gain_hold.y_output, pd.gain_input)
    connect(pd.torque_output, plant.get_actuation_input_port(arm.model_instance))

    f_WE = (
        task_scene.force_output_port(builder)
        if task_scene is not None
        else add("no_contact", ConstantVectorSource(np.zeros(3))).get_output_port()
    )
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
    widths = [FIELD_WIDTHS[name] for name in LOGGED_FIELDS]
    mux = add("log_mux", Multiplexer(widths))
    for i, name in enumerate(LOGGED_FIELDS):
        connect(sources[name], mux.get_input_port(i))
    logger = LogVectorOutput(mux.get_output_port(), builder, scenario.log_period)
    logger.set_name("logger")

    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    if recorder is not None:
        recorder.add_to_builder(builder, scene_graph)
    diagram = builder.Build()
    diagram.set_name("demonstration")
    return DemonstrationDiagram(diagram, plant, arm, plan, mapping, task_scene, logger)


def demonstration_from_log(log, seed):
    """The :class:`Demonstration` held by the logger's log (a ``VectorLog``)."""
    data = log.data()
    fields, row = {}, 0
    for name in LOGGED_FIELDS:
        width = FIELD_WIDTHS[name]
        block = data[row : row + width].T
        fields[name] = block[:, 0] if width == 1 else block
        row += width
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
            progress(
                f"demonstration {c}/{scenario.num_demonstrations} (seed {seed}): "
                f"{scenario.duration:g} s simulated in {time.perf_counter() - start:.1f} s"
                + (f", replay {replay}" if replay else "")
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
