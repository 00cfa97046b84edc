"""The autonomous reproduction diagram (the paper's Sec. III-C): HSMM-GMR drives the slave alone.

Signal flow (each box a system of this package or Drake, named as in the diagram)::

    reproducer --x_star--> clik --q_desired, v_desired--> pd --> plant
    x_star (default) or tool_point's p_WE --> reproducer (the position it observes)
    reproducer --k_star--> stiffness_limits --gain--> pd
    reproducer --x_star, xdot_star--> tracking_force (goal x_g) --F_tr--> exported port
    logger (every log_period): x*, xdot*, k*, h, p_WE, v_WE, f_WE, F_tr

No operator, master or sEMG: the reproducer (eqs. 12-18) generates the reference x*
(eq. 18) that CLIK (eq. 21) turns into a joint reference, and the stiffness k* that sets the
variable-gain PD's K (eq. 20). The tracking force of
eq. 23 is computed from x*, xdot* and the task's goal (the last waypoint of the scenario's
plan) and exported as the diagram's output port ``tracking_force``, to display on a master
when one is connected.

Modelling choices. The position x_t that the reproducer observes (input of its weights and
of GMR) is by default its own reference x*_t (``observe="reference"``): the learnt
dynamical system then runs on its own state, exactly as the numpy
:func:`~hemg_drake.learning.reproduce.reproduce`, and the slave tracks it with the learnt
stiffness. ``observe="tool"`` feeds the slave's actual tool point instead (the paper's
wording); then any tracking error the task imposes (the detent holding the pin while K is
low) is integrated into x* by eq. 18, and x* runs away from a slave that cannot follow
(measured on the cotter pin). k* is clipped to the scenario's [k_min, k_max] (Drake's
``Saturation``): GMR may extrapolate beyond the demonstrated gains, and the PD is only
checked inside its range. x*_0 is ``start`` (default: the demonstrations' start, the task
plan's first point), and the arm starts at rest where it settles in the task's scene while
the PD holds it there with the first k* (:func:`settled_arm_positions`): in free space
with its tool point on ``start`` (damped-Newton inverse kinematics of the demonstration
diagram); beside the cotter pin's grasped ring, where the PD balances the stretched grasp,
about 1 mm from the ring (the arm is much softer than the grasp). Started at rest on ``start``
instead, the grasp (150 N at 3 cm) would snap the tool back to the ring at 1.5 m/s in the
first 0.03 s: released springs, not the learnt task.

:func:`build_reproduction_diagram` builds it; :func:`run_reproduction` simulates it and
returns a :class:`ReproductionLog` and the task's outcome.
"""

import dataclasses as dc

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, Saturation

from hemg_drake.diagrams.slave import add_logger, add_slave, build_with_viewers, split_log
from hemg_drake.fileio import save_npz_atomic
from hemg_drake.learning.systems import HsmmGmrReproducer, TrackingForce
from hemg_drake.robots.baxter import FLOOR_Z
from hemg_drake.viz.ink import add_ink_to_recording, in_contact
from hemg_drake.viz.recording import ReplayRecorder

# Table I's K_pm = K_dm = 50, for eq. 23's K_ptr (N/m) and K_dtr (N s/m).
TRACKING_GAINS = (50.0, 50.0)
# What the reproducer observes as the current position (see the module notes).
OBSERVED = ("reference", "tool")
# Size of the model's position x (a point in space) and of its stiffness k.
POSITION_SIZE = 3
# A model is learnt over xi = [x, xdot, k]: D = 3 + 3 + 1.
MODEL_DIMENSION = 7
# Simulated time (s) for the arm to come to rest in the scene before a reproduction starts.
SETTLE_TIME = 1.0


@dc.dataclass(frozen=True, eq=False)
class ReproductionLog:
    """One reproduction as logged every ``log_period``; T samples, N HSMM states.

    Attributes
    ----------
    time : array, shape (T,), s.
    x_star, xdot_star : arrays, shape (T, 3), the reference (m, m/s; eqs. 15-18).
    k_star : array, shape (T,), the stiffness K fed to the PD (clipped to [k_min, k_max]).
    h : array, shape (T, N), the HSMM state weights (eq. 12).
    p_WE, v_WE : arrays, shape (T, 3), the slave's actual tool point (m, m/s).
    f_WE : array, shape (T, 3), force of the task on the tool point (N, W).
    F_tr : array, shape (T, 3), the tracking force of eq. 23 (N).
    """

    time: np.ndarray
    x_star: np.ndarray
    xdot_star: np.ndarray
    k_star: np.ndarray
    h: np.ndarray
    p_WE: np.ndarray
    v_WE: np.ndarray
    f_WE: np.ndarray
    F_tr: np.ndarray

    def observations(self):
        """[x, xdot, k] of the *actual* slave, shape (T, 7): what Table II compares."""
        return np.column_stack([self.p_WE, self.v_WE, self.k_star])

    def save(self, path):
        """Write the log to an NPZ file, atomically."""
        save_npz_atomic(path, **dc.asdict(self))


@dc.dataclass(frozen=True, eq=False)
class ReproductionDiagram:
    """A built reproduction diagram and handles into it.

    Attributes
    ----------
    diagram : Diagram
        Subsystems by name: ``plant``, ``scene_graph``, ``reproducer``, ``clik``, ``pd``,
        ``stiffness_limits``, ``tool_point``, ``tracking_force``, ``goal``, ``logger``;
        exported output port ``tracking_force`` (3, N).
    plant : MultibodyPlant
    arm : BaxterArm
    scene : object or None
        What the task's scene builder returned; None in free space.
    logger : VectorLogSink
    start : array, shape (3,), x*_0 (m), where the arm was held to rest.
    goal : array, shape (3,), x_g of eq. 23 (m).
    n_states : int, N.
    """

    diagram: object
    plant: object
    arm: object
    scene: object
    logger: object
    start: np.ndarray
    goal: np.ndarray
    n_states: int

    def log(self, context):
        """The :class:`ReproductionLog` recorded so far in the diagram's ``context``."""
        log = self.logger.FindLog(context)
        fields = split_log(log, _log_widths(self.n_states))
        fields["k_star"] = fields["k_star"][:, 0]
        return ReproductionLog(time=log.sample_times(), **fields)


def _log_widths(n_states):
    return {
        "x_star": 3, "xdot_star": 3, "k_star": 1, "h": n_states,
        "p_WE": 3, "v_WE": 3, "f_WE": 3, "F_tr": 3,
    }  # fmt: skip


def check_model(model):
    """Raise ValueError unless ``model`` is a fitted HSMM over [x, xdot, k] (D = 7)."""
    n_dims = model.n_dims_  # raises a ValueError if not fitted
    if n_dims != MODEL_DIMENSION or len(model.position_dims_) != POSITION_SIZE:
        raise ValueError(
            f"the model has D = {n_dims} dimensions with a {len(model.position_dims_)}-D "
            f"position; reproduction needs D = {MODEL_DIMENSION}: [x (3), xdot (3), k (1)]"
        )


def _add_slave(builder, scenario, start, *, scene, positions=None):
    """The shared slave side (:func:`~hemg_drake.diagrams.slave.add_slave`) with the
    reproduced stiffness k* clipped to [k_min, k_max] before the PD's gain.

    Returns the ``Slave`` and the ``stiffness_limits`` Saturation, whose input is left to
    connect.
    """
    slave = add_slave(builder, scenario, start=start, positions=positions, scene=scene)
    limits = builder.AddNamedSystem(
        "stiffness_limits", Saturation([scenario.emg.k_min], [scenario.emg.k_max])
    )
    builder.Connect(limits.get_output_port(), slave.gain_input)
    return slave, limits


def settled_arm_positions(scenario, start, gain, *, duration=SETTLE_TIME):
    """Where the arm comes to rest in the task's scene while the PD holds its tool at ``start``.

    Simulates the slave alone (no reproducer) for ``duration`` with the reference held at
    ``start`` and the gain at ``gain`` (its first k*), from the configuration that puts the
    tool point on ``start``. Free of contact this is that configuration; when the scene pulls
    on the tool there (the cotter pin's grasp, stretched by a start beside the ring) it is
    the static balance of the PD and the scene's force.

    Parameters
    ----------
    scenario : Scenario
    start : array, shape (3,), the held reference (m).
    gain : float or array of shape (1,), the PD's gain K.
    duration : float, s.

    Returns
    -------
    q : array, shape (7,), rad.
    """
    builder = DiagramBuilder()
    slave, limits = _add_slave(builder, scenario, start, scene=True)
    reference = builder.AddSystem(ConstantVectorSource(np.asarray(start, dtype=float)))
    stiffness = builder.AddSystem(ConstantVectorSource(np.atleast_1d(gain).astype(float)))
    builder.Connect(reference.get_output_port(), slave.p_WE_desired_input)
    builder.Connect(stiffness.get_output_port(), limits.get_input_port())
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(duration)
    plant_context = slave.plant.GetMyContextFromRoot(simulator.get_context())
    return slave.plant.GetPositions(plant_context, slave.arm.model_instance)


def build_reproduction_diagram(
    scenario,
    model,
    *,
    start=None,
    weighting="forward",
    restoring_gain=0.0,
    observe="reference",
    tracking_gains=TRACKING_GAINS,
    meshcat=None,
    recorder=None,
    scene=True,
):
    """Build the reproduction diagram of a learnt task.

    Parameters
    ----------
    scenario : Scenario
        The task (scene, plan, goal), the plant, CLIK settings and the gain range.
    model : HSMM
        Fitted over [x, xdot, k] (D = 7).
    start : array, shape (3,), optional
        x*_0 (m), where the arm is held when it starts (:func:`settled_arm_positions`);
        default the task plan's first point, where the demonstrations start.
    weighting : {"temporal", "spatial", "forward"}
        State weighting of the reproducer (:mod:`hemg_drake.learning.reproduce`).
    restoring_gain : float
        kappa of the reproducer's cross-track attractor (1/s; 0: eqs. 15-18 alone).
    observe : {"reference", "tool"}
        The position the reproducer observes: its own x* or the slave's tool point.
    tracking_gains : (float, float)
        K_ptr (N/m) and K_dtr (N s/m) of eq. 23.
    meshcat : Meshcat, optional
        Live view: a ``MeshcatVisualizer`` is added.
    recorder : ReplayRecorder, optional
        Attached to the scene graph, to record an HTML replay.
    scene : bool
        False leaves out the task's scene (free space, no force).

    Returns
    -------
    ReproductionDiagram

    Raises
    ------
    ValueError
        A model of another dimension or not fitted, a start of the wrong shape, NaN or out
        of the arm's reach, a bad weighting or gains.
    """
    check_model(model)
    if observe not in OBSERVED:
        raise ValueError(f"observe must be one of {OBSERVED}, got {observe!r}")
    plan = scenario.task_plan()
    start = plan.points[0] if start is None else np.asarray(start, dtype=float)
    if start.shape != (3,) or not np.all(np.isfinite(start)):
        raise ValueError(f"start must be 3 finite numbers (m), got {start!r}")
    goal = np.array(plan.points[-1], dtype=float)

    reproducer = HsmmGmrReproducer(
        model=model,
        start=start,
        dt=scenario.log_period,
        weighting=weighting,
        restoring_gain=restoring_gain,
    )
    gain_0 = reproducer.GetOutputPort("k_star").Eval(reproducer.CreateDefaultContext())
    q_0 = settled_arm_positions(scenario, start, gain_0) if scene else None

    builder = DiagramBuilder()
    slave, limits = _add_slave(builder, scenario, start, scene=scene, positions=q_0)
    plant, scene_graph, arm, task_scene = slave.plant, slave.scene_graph, slave.arm, slave.scene
    tool_point = slave.tool_point

    def add(name, system):
        return builder.AddNamedSystem(name, system)

    add("reproducer", reproducer)
    kp, kd = tracking_gains
    tracking = add("tracking_force", TrackingForce(kp=kp, kd=kd))
    goal_source = add("goal", ConstantVectorSource(goal))

    connect = builder.Connect
    observed = tool_point.p_WE_output if observe == "tool" else reproducer.GetOutputPort("x_star")
    connect(observed, reproducer.GetInputPort("p_WE"))
    connect(reproducer.GetOutputPort("x_star"), slave.p_WE_desired_input)
    connect(reproducer.GetOutputPort("k_star"), limits.get_input_port())
    connect(reproducer.GetOutputPort("x_star"), tracking.GetInputPort("x_star"))
    connect(reproducer.GetOutputPort("xdot_star"), tracking.GetInputPort("xdot_star"))
    connect(goal_source.get_output_port(), tracking.GetInputPort("x_goal"))
    builder.ExportOutput(tracking.GetOutputPort("F_tr"), "tracking_force")

    f_WE = slave.f_WE_output
    sources = {
        "x_star": reproducer.GetOutputPort("x_star"),
        "xdot_star": reproducer.GetOutputPort("xdot_star"),
        "k_star": limits.get_output_port(),
        "h": reproducer.GetOutputPort("h"),
        "p_WE": tool_point.p_WE_output,
        "v_WE": tool_point.v_WE_output,
        "f_WE": f_WE,
        "F_tr": tracking.GetOutputPort("F_tr"),
    }
    logger = add_logger(
        builder, {name: sources[name] for name in _log_widths(model.n_states)}, scenario.log_period
    )
    diagram = build_with_viewers(
        builder, scene_graph, "reproduction", meshcat=meshcat, recorder=recorder
    )
    return ReproductionDiagram(
        diagram, plant, arm, task_scene, logger, start.copy(), goal, model.n_states
    )


@dc.dataclass(frozen=True, eq=False)
class ReproductionResult:
    """What :func:`run_reproduction` returns.

    Attributes
    ----------
    log : ReproductionLog
    pin_displacement : float or None
        Cotter pin: the pin's withdrawal at the end (m); None for other tasks.
    pin_out : bool or None
        Cotter pin: withdrawn by at least its length.
    """

    log: ReproductionLog
    pin_displacement: float = None
    pin_out: bool = None


def run_reproduction(
    scenario,
    model,
    *,
    duration=None,
    start=None,
    weighting="forward",
    restoring_gain=0.0,
    observe="reference",
    replay_path=None,
    scene=True,
):
    """Simulate a reproduction.

    Parameters
    ----------
    scenario, model, start, weighting, restoring_gain, observe, scene
        As :func:`build_reproduction_diagram`.
    duration : float, optional
        Simulated seconds; default ``scenario.duration`` (a demonstration's length).
    replay_path : path-like, optional
        Write a self-contained HTML replay there.

    Returns
    -------
    ReproductionResult
    """
    duration = scenario.duration if duration is None else float(duration)
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be a positive number of seconds, got {duration}")
    recorder = None if replay_path is None else ReplayRecorder(floor_z=FLOOR_Z)
    built = build_reproduction_diagram(
        scenario,
        model,
        start=start,
        weighting=weighting,
        restoring_gain=restoring_gain,
        observe=observe,
        recorder=recorder,
        scene=scene,
    )
    simulator = Simulator(built.diagram)
    simulator.Initialize()
    if recorder is not None:
        recorder.start()
    # The logger samples at multiples of log_period; reach the last one.
    simulator.AdvanceTo(duration + 1e-9)
    context = simulator.get_context()
    log = built.log(context)
    if recorder is not None:
        if scene and scenario.task == "drawing":
            # Just above the sheet: the tip's own heights are inside the compliant paper.
            height = built.scene.paper_height + 5e-4
            touching = in_contact(log.f_WE)
            add_ink_to_recording(recorder.meshcat, log.time, log.p_WE, touching, height=height)
        recorder.stop_and_export(replay_path)
    if not (scene and scenario.task == "cotter_pin"):
        return ReproductionResult(log=log)
    plant_context = built.plant.GetMyContextFromRoot(context)
    return ReproductionResult(
        log=log,
        pin_displacement=built.scene.pin_displacement(plant_context),
        pin_out=bool(built.scene.pin_out(plant_context)),
    )
