"""The autonomous reproduction diagram (the paper's Sec. III-C): HSMM-GMR drives the slave alone.

Signal flow (each box a system of this package or Drake, named as in the diagram)::

    reproducer --x_star--> station (clik -> pd -> plant)
    x_star (default) or the station's p_WE --> reproducer (the position it observes)
    reproducer --k_star--> stiffness_limits --gain--> station
    reproducer --stiffness_shape--> station        (reproduction.stiffness: spd only)
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
plan's first point); :func:`run_reproduction` first lets the arm come to rest holding it, in
this same diagram with the reproducer holding (no second station).

:func:`build_reproduction_diagram` builds it (and only builds); :func:`run_reproduction`
simulates a built diagram and returns a :class:`ReproductionLog` and the task's outcome.
Every setting is the scenario's (``reproduction`` section).
"""

import dataclasses as dc

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, Saturation, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from hemg_drake._validate import as_vector
from hemg_drake.control.clik import velocity_columns
from hemg_drake.control.push import ToolPointForce, push_trajectory
from hemg_drake.diagrams.built import StationDiagram, make_simulator
from hemg_drake.diagrams.log import add_logger, split_log
from hemg_drake.diagrams.station import make_slave_station
from hemg_drake.robots.baxter import make_arm_controller_plant
from hemg_drake.learning.systems import (
    HsmmGmrReproducer,
    HsmmLqrReproducer,
    TrackingForce,
    set_holding,
)

# Size of the model's position x (a point in space) and of its stiffness k.
POSITION_SIZE = 3
# A model is learnt over xi = [x, xdot, k]: D = 3 + 3 + 1.
MODEL_DIMENSION = 7


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
    stiffness_shape : array, shape (T, 9), or None
        ``reproduction.stiffness: spd``: the Cartesian stiffness' shape S_hat fed to the
        station (row-major 3 x 3, unit determinant); None in the scalar case.
    tau : array, shape (T, 7), or None, the PD's joint torques (N m).
    f_block : array, shape (T, 3), or None
        The contact force on ``scene.block`` (N, W); None without a block.
    f_push : array, shape (T, 3), or None
        The push at the tool point (``reproduction.push``, N, W); None without one.
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
    stiffness_shape: np.ndarray = None
    tau: np.ndarray = None
    f_block: np.ndarray = None
    f_push: np.ndarray = None

    def observations(self):
        """[x, xdot, k] of the *actual* slave, shape (T, 7): what Table II compares."""
        return np.column_stack([self.p_WE, self.v_WE, self.k_star])

    def arrays(self):
        """The log as a dict of arrays (for an NPZ file); None fields left out."""
        return {name: value for name, value in dc.asdict(self).items() if value is not None}


@dc.dataclass(frozen=True, eq=False)
class ReproductionDiagram(StationDiagram):
    """A built reproduction diagram and handles into it.

    Attributes
    ----------
    diagram : Diagram
        Subsystems by name: ``station``, ``reproducer``, ``stiffness_limits``,
        ``tracking_force``, ``goal``, ``logger``; exported output port ``tracking_force``
        (3, N).
    station : SlaveStation
    scenario : Scenario
    model : HSMM
    logger : VectorLogSink
    start : array, shape (3,), x*_0 (m), where the arm is held to rest.
    goal : array, shape (3,), x_g of eq. 23 (m).
    """

    scenario: object
    model: object
    logger: object
    start: np.ndarray
    goal: np.ndarray

    def log(self, context):
        """The :class:`ReproductionLog` recorded so far in the diagram's ``context``."""
        log = self.logger.FindLog(context)
        widths = _log_widths(self.model.n_states, self.scenario, self.scene is not None)
        fields = split_log(log, widths)
        fields["k_star"] = fields["k_star"][:, 0]
        return ReproductionLog(time=log.sample_times(), **fields)


def _log_widths(n_states, scenario, scene=True):
    widths = {
        "x_star": 3, "xdot_star": 3, "k_star": 1, "h": n_states,
        "p_WE": 3, "v_WE": 3, "f_WE": 3, "F_tr": 3,
    }  # fmt: skip
    if scenario.reproduction.stiffness == "spd":
        widths["stiffness_shape"] = 9
    widths["tau"] = 7
    if scene and scenario.scene.block.size:
        widths["f_block"] = 3
    if scenario.reproduction.push.force:
        widths["f_push"] = 3
    return widths


def check_model(model):
    """Raise ValueError unless ``model`` is a fitted HSMM over [x, xdot, k] (D = 7)."""
    n_dims = model.n_dims_  # raises a ValueError if not fitted
    if n_dims != MODEL_DIMENSION or len(model.position_dims_) != POSITION_SIZE:
        raise ValueError(
            f"the model has D = {n_dims} dimensions with a {len(model.position_dims_)}-D "
            f"position; reproduction needs D = {MODEL_DIMENSION}: [x (3), xdot (3), k (1)]"
        )


def make_reproducer(scenario, model, start):
    """The reproducer of the scenario's ``reproduction.tracker``: ``HsmmGmrReproducer``
    (eqs. 12-18) or ``HsmmLqrReproducer`` (the LQR tracker), at the log period."""
    settings = scenario.reproduction
    common = dict(
        model=model, start=start, dt=scenario.log_period, weighting=settings.weighting,
        stiffness_ratio=settings.stiffness_ratio,
        stiffness_normalisation=settings.stiffness_normalisation,
    )  # fmt: skip
    if settings.tracker == "gmr":
        return HsmmGmrReproducer(**common, restoring_gain=settings.restoring_gain)
    return HsmmLqrReproducer(
        **common,
        horizon=settings.horizon,
        control_cost=settings.control_cost,
        max_lead=settings.max_lead,
        state_cost=settings.state_cost,
    )


def _add_station(builder, scenario, start, *, scene, q0=None, visualization=None):
    """The station, with the reproduced stiffness k* clipped to [k_min, k_max] before its
    gain input. Returns the station and the ``stiffness_limits`` Saturation."""
    station = make_slave_station(
        scenario, start=start, q0=q0, scene=scene, visualization=visualization,
        stiffness=scenario.reproduction.stiffness,
    )  # fmt: skip
    slave = builder.AddSystem(station.diagram)
    limits = builder.AddNamedSystem(
        "stiffness_limits", Saturation([scenario.emg.k_min], [scenario.emg.k_max])
    )
    builder.Connect(limits.get_output_port(), slave.GetInputPort("gain"))
    return station, limits


def settled_plant_state(built):
    """The plant's state [q; v] (arm and scene) at rest while the PD holds its tool at x*_0.

    Simulates ``built.diagram`` itself, in a context of its own, for
    ``reproduction.settle_time`` with the reproducer holding (its ``holding`` parameter:
    x*_0 and the first k* stay put) from the configuration that puts the tool point on
    x*_0. Free of contact this is that configuration; when the scene pulls on the tool there
    (the cotter pin's grasp, stretched by a start beside the ring) it is the static balance
    of the PD and the scene's force. The scene's bodies settle too, and the run starts from
    all of it: a start above the ring draws the pin out to it (the detent gives at 50 N);
    restarting that pin at rest in the fixture under the settled arm would stretch the grasp
    to 150 N at t = 0 (issue 23).

    Returns
    -------
    array, shape (nq + nv,): the plant's positions and velocities (m, rad, m/s, rad/s).
    """
    diagram, station = built.diagram, built.station
    context = diagram.CreateDefaultContext()
    reproducer = diagram.GetSubsystemByName("reproducer")
    set_holding(reproducer, reproducer.GetMyMutableContextFromRoot(context), True)
    if diagram.HasSubsystemNamed("push"):  # the settling is not pushed
        push = diagram.GetSubsystemByName("push")
        push.set_enabled(push.GetMyMutableContextFromRoot(context), False)
    simulator = Simulator(diagram, context)
    simulator.AdvanceTo(built.scenario.reproduction.settle_time)
    return station.plant.GetPositionsAndVelocities(station.plant_context(context))


def _gain_source(builder, scenario, reproducer, demonstrated_gain):
    """The output port of the gain K before its limits: k* (``reproduction.gain_source``
    "learnt"), a ``ConstantVectorSource`` ("constant") or a ``TrajectorySource`` of the
    demonstrations' K ("demonstrated": (times, K), first-order hold, held at the ends)."""
    settings = scenario.reproduction
    if settings.gain_source == "learnt":
        return reproducer.GetOutputPort("k_star")
    if settings.gain_source == "constant":
        source = ConstantVectorSource([settings.constant_gain])
    else:
        if demonstrated_gain is None:
            raise ValueError(
                "reproduction.gain_source 'demonstrated' needs the demonstrations' gain "
                "(build_reproduction_diagram(..., demonstrated_gain=(times, K)))"
            )
        times, gain = (np.asarray(a, dtype=float) for a in demonstrated_gain)
        source = TrajectorySource(PiecewisePolynomial.FirstOrderHold(times, gain[None, :]))
    return builder.AddNamedSystem("gain_source", source).get_output_port()


def _add_push(builder, scenario, station, slave):
    """``reproduction.push``: its force (in T, turned into W) over time from a
    ``TrajectorySource``, at the tool point through :class:`~hemg_drake.control.push.
    ToolPointForce` into the station's ``applied_generalized_force``. Returns the force's
    output port (for the log)."""
    push = scenario.reproduction.push
    f_W = scenario.X_WT().rotation().matrix() @ np.asarray(push.force, dtype=float)
    force = builder.AddNamedSystem(
        "push_force", TrajectorySource(push_trajectory(f_W, push.start, push.duration))
    )
    controller_plant, controller_arm = make_arm_controller_plant()
    system = builder.AddNamedSystem("push", ToolPointForce(
        controller_plant=controller_plant, arm=controller_arm,
        columns=velocity_columns(station.plant, station.arm.model_instance),
        num_velocities=station.plant.num_velocities(),
    ))  # fmt: skip
    builder.Connect(slave.GetOutputPort("arm_state"), system.arm_state_input)
    builder.Connect(force.get_output_port(), system.f_W_input)
    builder.Connect(
        system.generalized_force_output, slave.GetInputPort("applied_generalized_force")
    )
    return force.get_output_port()


def build_reproduction_diagram(
    scenario, model, *, start=None, visualization=None, scene=True, demonstrated_gain=None
):
    """Build the reproduction diagram of a learnt task (it only builds; see
    :func:`run_reproduction`).

    Every setting comes from the scenario (``reproduction``: weighting, restoring gain,
    the observed position, eq. 23's gains; ``emg``: the gain range), so the library with its
    defaults builds what the CLI builds.

    Parameters
    ----------
    scenario : Scenario
        The task (scene, plan, goal), the plant, CLIK settings, the gain range and the
        reproduction's settings.
    model : HSMM
        Fitted over [x, xdot, k] (D = 7).
    start : array, shape (3,), optional
        x*_0 (m); default the task plan's first point, where the demonstrations start.
    visualization : Visualization, optional
        Show the station in its (loopback) Meshcat with ``scenario.visualization``.
    scene : bool
        False leaves out the task's scene (free space, no force).
    demonstrated_gain : (array (n,), array (n,)), optional
        Times (s) and the demonstrations' gain K there: needed by
        ``reproduction.gain_source: demonstrated``.

    Returns
    -------
    ReproductionDiagram

    Raises
    ------
    ValueError
        A model of another dimension or not fitted, a start of the wrong shape, NaN or out
        of the arm's reach.
    """
    check_model(model)
    settings = scenario.reproduction
    plan = scenario.task_plan()
    start = plan.points[0] if start is None else as_vector("start", start, 3)
    goal = np.array(plan.points[-1], dtype=float)

    builder = DiagramBuilder()
    station, limits = _add_station(
        builder, scenario, start, scene=scene, visualization=visualization
    )
    slave = builder.GetSubsystemByName(station.diagram.get_name())

    def add(name, system):
        return builder.AddNamedSystem(name, system)

    reproducer = add("reproducer", make_reproducer(scenario, model, start))
    kp, kd = settings.tracking_gains
    tracking = add("tracking_force", TrackingForce(kp=kp, kd=kd))
    goal_source = add("goal", ConstantVectorSource(goal))

    connect = builder.Connect
    # The LQR tracker re-plans from the measured tool point: that is its feedback.
    measured = settings.observe == "tool" or settings.tracker == "lqr"
    observed = slave.GetOutputPort("p_WE") if measured else reproducer.GetOutputPort("x_star")
    connect(observed, reproducer.GetInputPort("p_WE"))
    connect(reproducer.GetOutputPort("x_star"), slave.GetInputPort("p_WE_desired"))
    connect(_gain_source(builder, scenario, reproducer, demonstrated_gain),
            limits.get_input_port())  # fmt: skip
    spd = settings.stiffness == "spd"
    if spd:
        connect(reproducer.GetOutputPort("stiffness_shape"), slave.GetInputPort("stiffness_shape"))
    connect(reproducer.GetOutputPort("x_star"), tracking.GetInputPort("x_star"))
    connect(reproducer.GetOutputPort("xdot_star"), tracking.GetInputPort("xdot_star"))
    connect(goal_source.get_output_port(), tracking.GetInputPort("x_goal"))
    builder.ExportOutput(tracking.GetOutputPort("F_tr"), "tracking_force")

    sources = {
        "x_star": reproducer.GetOutputPort("x_star"),
        "xdot_star": reproducer.GetOutputPort("xdot_star"),
        "k_star": limits.get_output_port(),
        "h": reproducer.GetOutputPort("h"),
        "p_WE": slave.GetOutputPort("p_WE"),
        "v_WE": slave.GetOutputPort("v_WE"),
        "f_WE": slave.GetOutputPort("f_WE"),
        "F_tr": tracking.GetOutputPort("F_tr"),
        "stiffness_shape": reproducer.GetOutputPort("stiffness_shape"),
        "tau": slave.GetOutputPort("tau"),
    }
    if settings.push.force:
        sources["f_push"] = _add_push(builder, scenario, station, slave)
    if slave.HasOutputPort("f_block"):
        sources["f_block"] = slave.GetOutputPort("f_block")
    widths = _log_widths(model.n_states, scenario, scene)
    logger = add_logger(builder, {name: sources[name] for name in widths}, scenario.log_period)
    diagram = builder.Build()
    diagram.set_name("reproduction")
    return ReproductionDiagram(
        diagram=diagram,
        station=station,
        scenario=scenario,
        model=model,
        logger=logger,
        start=start.copy(),
        goal=goal,
    )


@dc.dataclass(frozen=True, eq=False)
class ReproductionResult:
    """What :func:`run_reproduction` returns.

    Attributes
    ----------
    log : ReproductionLog
    q0 : array, shape (7,), the arm's configuration at the start (rad).
    pin_displacement : float or None
        Cotter pin: the pin's withdrawal at the end (m); None for other tasks.
    pin_out : bool or None
        Cotter pin: withdrawn by at least its length.
    """

    log: ReproductionLog
    q0: np.ndarray
    pin_displacement: float = None
    pin_out: bool = None


def run_reproduction(built, *, duration=None, settle=True):
    """Simulate a built reproduction diagram.

    Before the reproduction starts, the arm is brought to rest where it settles in the
    task's scene while the PD holds the tool at x*_0 with the first k*
    (:func:`settled_plant_state`, a run of this same diagram with the reproducer holding;
    ``settle=False`` starts it on x*_0 by inverse
    kinematics). Beside the cotter pin's grasped ring, where the PD balances the stretched
    grasp, that is about 1 mm from the ring (the arm is much softer than the grasp);
    started on a point 3 cm aside instead, the grasp (150 N at 3 cm) would snap the tool
    back to the ring at 1.5 m/s in the first 0.03 s: released springs, not the learnt task.

    Parameters
    ----------
    built : ReproductionDiagram
    duration : float, optional
        Simulated seconds; default ``scenario.duration`` (a demonstration's length).
    settle : bool

    Returns
    -------
    ReproductionResult
    """
    scenario = built.scenario
    station = built.station
    # Settled first, in a context of its own: the arm and the scene start this run at rest
    # there.
    settled = settled_plant_state(built) if settle and built.scene is not None else None
    simulator, duration = make_simulator(built, duration)
    context = simulator.get_mutable_context()
    plant_context = station.plant_context(context)
    if settled is None:
        station.plant.SetPositions(plant_context, station.arm.model_instance, station.q0)
    else:
        station.plant.SetPositionsAndVelocities(plant_context, settled)
    q0 = station.plant.GetPositions(plant_context, station.arm.model_instance)
    simulator.Initialize()
    # The logger samples at multiples of log_period; reach the last one.
    simulator.AdvanceTo(duration + 1e-9)
    log = built.log(context)
    if not (built.scene is not None and scenario.task == "cotter_pin"):
        return ReproductionResult(log=log, q0=q0)
    return ReproductionResult(
        log=log,
        q0=q0,
        pin_displacement=built.scene.pin_displacement(plant_context),
        pin_out=bool(built.scene.pin_out(plant_context)),
    )
