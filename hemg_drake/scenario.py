"""Scenarios: everything a run depends on, as data: dataclasses read from YAML.

A scenario file is one YAML mapping whose keys are the fields of :class:`Scenario` (nested
sections for the sub-dataclasses); every key may be left out to take its default. Every
default exists once: a section that configures a system of this package takes its defaults
from that system's own signature (``_default``), so ``Scenario()`` builds exactly the
systems the library builds with its defaults. The plant and the simulator are configured
by Drake's own ``MultibodyPlantConfig`` and ``SimulatorConfig``; the scene's physics by the
task modules' ``CotterPinParams`` and ``DrawingParams``.

It is read with Drake's ``yaml_load_typed`` (which refuses unknown keys and wrong types);
:func:`load_scenario` adds what that does not check (the key path of a wrongly typed value,
vector sizes, finite and non-negative numbers, choices) and reports every problem as one
``ValueError`` naming the file and the key. Any key can be overridden with
``overrides=["emg.k_max=150", "scene.position=[0.65, -0.80, 0.12]"]`` (YAML value syntax;
the CLI's ``--set``)::

    scenario = load_scenario(shipped_scenario("cotter_pin"), overrides=["scene.yaw_deg=20"])
    plan = scenario.task_plan()          # in the world, where the scene stands
"""

import dataclasses as dc
import importlib.resources
import inspect
import math
import re
import typing
from pathlib import Path

import numpy as np
import yaml
from pydrake.common.yaml import yaml_dump_typed, yaml_load, yaml_load_typed
from pydrake.math import RollPitchYaw, RotationMatrix
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.analysis import SimulatorConfig

from hemg_drake.control.clik import CLIK_METHODS, Clik
from hemg_drake.control.pd import MAX_TIME_STEP
from hemg_drake.emg.envelope import RmsEnvelope
from hemg_drake.emg.gain import VariableGain
from hemg_drake.emg.sources import MYO_RATE
from hemg_drake.fileio import read_yaml_text
from hemg_drake.learning.hsmm import HSMM, INITS as HSMM_INITS
from hemg_drake.learning.reproduce import STATE_COSTS, TRACKERS, WEIGHTINGS, reproduce
from hemg_drake.learning.systems import HsmmLqrReproducer
from hemg_drake.tasks import cotter_pin, drawing
from hemg_drake.tasks.cotter_pin import CotterPinParams
from hemg_drake.tasks.drawing import DrawingParams
from hemg_drake.tasks.placement import scene_pose, to_world
from hemg_drake.tasks.plan import TaskPlan
from hemg_drake.teleop.feedback import MODES as FEEDBACK_MODES
from hemg_drake.teleop.feedback import PASSIVITY as FEEDBACK_PASSIVITY
from hemg_drake.teleop.feedback import ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMap, WorkspaceMapping
from hemg_drake.teleop.master import MasterDynamics
from hemg_drake.teleop.operator import OperatorModel
from hemg_drake.yaml_schema import check_types, first_line, schema_fields

TASKS = ("cotter_pin", "drawing")
# Where a demonstration's raw sEMG comes from (emg.source).
EMG_SOURCES = ("synthetic", "myo", "libemg")
# Longest demonstration (s): 10 minutes of a 1 kHz diagram is minutes to simulate and about
# 0.5 GB of logs; a longer one is more likely a typo than a plan.
MAX_DURATION = 600.0
# Where each task's scene stands by default (scene frame T's origin, m, in W).
DEFAULT_POSITIONS = {"cotter_pin": cotter_pin.DEFAULT_POSITION, "drawing": drawing.DEFAULT_POSITION}
# The scenarios shipped with the package (hemg_drake/scenarios/<name>.yaml).
SCENARIOS = importlib.resources.files("hemg_drake") / "scenarios"


def _default(function, name):
    """The default of ``function``'s parameter ``name``: the one source of that default."""
    return inspect.signature(function).parameters[name].default


def _value(default, **checks):
    """A dataclass field with its default and its range checks, read by ``_check_values``.

    Checks (numbers must be >= 0 unless ``signed``): ``positive``, ``signed``, ``fraction``
    (in [0, 1]), ``maximum``, ``size`` (a vector's length), ``choices`` (allowed values).
    """
    if isinstance(default, (list, tuple, np.ndarray)):
        items = list(default)
        return dc.field(default_factory=lambda: list(items), metadata=checks)
    return dc.field(default=default, metadata=checks)


def _field(function, name, **checks):
    """A field whose default is ``function``'s default for ``name`` (see :func:`_value`)."""
    value = _default(function, name)
    if isinstance(value, (list, tuple, np.ndarray)):
        value = [float(v) for v in value]
    return _value(value, **checks)


@dc.dataclass
class PlacementsConfig:
    """A scene placement per demonstration (``hemg_drake.placements``): each demonstration's
    seed draws its scene pose uniformly from these ranges; empty: ``scene.position`` /
    ``scene.yaw_deg`` for every demonstration."""

    # Box of scene positions (m, in W): [[xmin, ymin, zmin], [xmax, ymax, zmax]].
    position_range: list[list[float]] = _value([], signed=True)
    # Range of scene yaws (deg): [smallest, largest].
    yaw_range_deg: list[float] = _value([], signed=True, size=(0, 2))


@dc.dataclass
class SceneConfig:
    """Where the task's object stands, and its physics (the scene frame T)."""

    # Position of the scene frame T in the world (m): the cotter pin's ring centre with the
    # pin in; the sheet's top-surface centre. Empty: the task's default (DEFAULT_POSITIONS).
    # The operator's plan and the workspace map move with it.
    position: list[float] = _value([], signed=True, size=(0, 3))
    # Turn of the scene about world +z (deg): the fixture, the sheet and its strokes, the
    # plan and the master's frame turn with it (the pin's pull axis stays world +z).
    yaw_deg: float = _value(0.0, signed=True)
    # The cotter pin's detent, friction and grasp (used when task is cotter_pin).
    cotter_pin: CotterPinParams = dc.field(default_factory=CotterPinParams)
    # The pen, its contact and the plan's heights (used when task is drawing).
    drawing: DrawingParams = dc.field(default_factory=DrawingParams)
    # Demonstrations at many placements: ranges each demonstration's seed draws its pose from.
    placements: PlacementsConfig = dc.field(default_factory=PlacementsConfig)


@dc.dataclass
class PlanConfig:
    """A task plan written out in the scenario (see :class:`~hemg_drake.tasks.plan.TaskPlan`)."""

    # Waypoint times (s), strictly increasing, at least two.
    times: list[float] = dc.field(default_factory=list)
    # Waypoints of the tool point in the scene frame T (m), one [x, y, z] per time; the
    # scene's pose maps them to the world.
    points: list[list[float]] = _value([], signed=True)
    # "free" or "forceful", one per segment (between consecutive waypoints).
    kinds: list[str] = dc.field(default_factory=list)
    # Drawing: the pen touches the paper, one flag per segment (empty: all False).
    pen_down: list[bool] = dc.field(default_factory=list)
    # Operator's effort per segment relative to nominal, > 0 (empty: all 1).
    effort: list[float] = dc.field(default_factory=list)


@dc.dataclass
class MappingConfig:
    """Master-to-slave workspace map (:class:`~hemg_drake.teleop.mapping.WorkspaceMapping`)."""

    # Slave metres per master metre.
    scale: float = _value(WorkspaceMapping.__dataclass_fields__["scale"].default, positive=True)
    # The slave point that the centre of the master's workspace maps to, from the scene
    # frame's origin, in the scene frame T (m): the map follows the scene.
    scene_offset: list[float] = _value([0.0, 0.0, 0.0], signed=True, size=3)
    # Orientation of the master frame M relative to the scene frame T, roll-pitch-yaw in
    # degrees (R_WM = R_WT R_TM). The default puts the operator behind the robot, facing
    # the way it faces.
    rpy_deg: list[float] = _value([90.0, 0.0, -90.0], signed=True, size=3)
    # Constant transport delay of the teleoperation channel, in master samples (1 ms each).
    delay_steps: int = _field(WorkspaceMap.__init__, "delay_steps")


@dc.dataclass
class MasterConfig:
    """Touch X tip dynamics (:class:`~hemg_drake.teleop.master.HapticMaster`), SI units."""

    # Apparent mass at the tip (kg).
    mass: float = _field(MasterDynamics.__init__, "mass", positive=True)
    # Viscous backdrive damping (N s/m).
    damping: float = _field(MasterDynamics.__init__, "damping")
    # Coulomb backdrive friction (N).
    friction: float = _field(MasterDynamics.__init__, "friction")
    # Motor force saturation (N), the Touch X peak force.
    peak_force: float = _field(MasterDynamics.__init__, "peak_force")
    # Workspace box, width x height x depth (m).
    workspace_size: list[float] = _field(
        MasterDynamics.__init__, "workspace_size", positive=True, size=3
    )
    # Soft walls beyond the box: spring (N/m) and damper (N s/m).
    wall_stiffness: float = _field(MasterDynamics.__init__, "wall_stiffness")
    wall_damping: float = _field(MasterDynamics.__init__, "wall_damping")
    # Sample period of the haptic loop (s): the device's servo rate, 1 kHz.
    period: float = _field(MasterDynamics.__init__, "period", positive=True)


@dc.dataclass
class OperatorConfig:
    """The simulated operator (:class:`~hemg_drake.teleop.operator.SimulatedOperator`) and
    its seeded variability between demonstrations."""

    # Hand impedance pushing the stylus toward the planned point, in the master frame:
    # stiffness (N/m), damping (N s/m), and the saturation of the hand force's norm (N).
    hand_stiffness: float = _field(OperatorModel.__init__, "hand_stiffness", positive=True)
    hand_damping: float = _field(OperatorModel.__init__, "hand_damping")
    max_hand_force: float = _field(OperatorModel.__init__, "max_hand_force")
    # Muscle activation in [0, 1]: relaxed, moving freely, working against the task (at
    # effort 1).
    rest_activation: float = _field(OperatorModel.__init__, "rest_activation", fraction=True)
    free_activation: float = _field(OperatorModel.__init__, "free_activation", fraction=True)
    forceful_activation: float = _field(
        OperatorModel.__init__, "forceful_activation", fraction=True
    )
    # Co-contraction: activation added per newton of force felt on the stylus (1/N).
    co_contraction_gain: float = _field(OperatorModel.__init__, "co_contraction_gain")
    # Time constant of the muscle activation (s).
    activation_time_constant: float = _field(
        OperatorModel.__init__, "activation_time_constant", positive=True
    )
    # Sample period of the activation (s): the MYO's 1/200 s, the rate at which the sEMG
    # source reads it.
    period: float = _field(OperatorModel.__init__, "period", positive=True)
    # Variability (TaskPlan.perturbed): log-normal spread of each segment's duration, the
    # path offset's standard deviation per world axis (m), log-normal spread of the effort.
    timing_std: float = _field(TaskPlan.perturbed, "timing_std")
    path_std: list[float] = _value([_default(TaskPlan.perturbed, "path_std")] * 3, size=3)
    effort_std: float = _field(TaskPlan.perturbed, "effort_std")

    def model_parameters(self):
        """Keyword arguments of ``SimulatedOperator`` (all fields but the variability)."""
        data = dc.asdict(self)
        for name in ("timing_std", "path_std", "effort_std"):
            del data[name]
        return data


@dc.dataclass
class EmgConfig:
    """sEMG chain: synthetic MYO source, RMS envelope (eqs. 1-2), gain law (eq. 22)."""

    # Moving-RMS window L_win in 200 Hz samples (the paper picks 20).
    window: int = _field(RmsEnvelope.__init__, "window", positive=True)
    # RMS per channel, then summed, instead of the paper's RMS of the channel sum.
    per_channel: bool = _field(RmsEnvelope.__init__, "per_channel")
    # Shape factor of the activation curve (Table I).
    A_emg: float = _field(VariableGain.__init__, "A_emg", signed=True)
    # Gain K at rest and at maximum contraction (VariableGainPd's K; its tested range is
    # 5 to 500, Table I's 50 sits between).
    k_min: float = _field(VariableGain.__init__, "k_min")
    k_max: float = _field(VariableGain.__init__, "k_max")
    # Length of the synthetic rest and maximum-contraction recordings (s) from which the
    # envelope's calibration is computed before each demonstration.
    calibration_duration: float = _value(2.0, positive=True)
    # Where the raw sEMG comes from: "synthetic" (SyntheticEmgSource, driven by the
    # operator's activation), or a live armband read by LiveEmgSource: "myo" (pyomyo,
    # hemg-drake[myo]) or "libemg" (a LibEMG streamer's shared memory, tag libemg_tag).
    # A live source needs the simulator at real time (simulator.target_realtime_rate: 1,
    # as hemg-drake teleop runs).
    source: str = _value("synthetic", choices=EMG_SOURCES)
    libemg_tag: str = "emg"


@dc.dataclass
class ClikConfig:
    """Closed-loop inverse kinematics (:class:`~hemg_drake.control.clik.Clik`, eq. 21)."""

    # K_sp: 1/(m^2 s) for "transpose", 1/s for "dls".
    gain: float = _field(Clik.__init__, "gain", positive=True)
    # "transpose" (the paper's J^T law) or "dls" (damped least squares).
    method: str = _field(Clik.__init__, "method", choices=CLIK_METHODS)
    # Damping of the "dls" law (m).
    damping: float = _field(Clik.__init__, "damping")
    # Update period (s).
    period: float = _field(Clik.__init__, "period", positive=True)
    # Optional orientation task in the null space of eq. 21's position task: the tool
    # frame's axis axis_E (in E) is turned towards axis_W_desired (in W) at this rate
    # (1/s); 0 leaves the paper's position-only law. The drawing holds its pen down.
    orientation_gain: float = _field(Clik.__init__, "orientation_gain")
    axis_E: list[float] = _field(Clik.__init__, "axis_E", signed=True, size=3)
    axis_W_desired: list[float] = _field(Clik.__init__, "axis_W_desired", signed=True, size=3)


@dc.dataclass
class FeedbackConfig:
    """Force fed back to the master (:class:`~hemg_drake.teleop.feedback.ForceFeedback`)."""

    # "force": the slave's interaction force; "position_error": the master PD of Table I.
    mode: str = _field(ForceFeedback.__init__, "mode", choices=FEEDBACK_MODES)
    # Extra scale on the force in mode "force" (dimensionless).
    gain: float = _field(ForceFeedback.__init__, "gain")
    # K_pm (N/m) and K_dm (N s/m) in mode "position_error" (Table I: 50 and 50).
    stiffness: float = _field(ForceFeedback.__init__, "stiffness")
    damping: float = _field(ForceFeedback.__init__, "damping")
    # Saturation of the motor force (N).
    peak_force: float = _field(ForceFeedback.__init__, "peak_force")
    # Slave-to-master transport delay of the fed-back force (or of the slave's position in
    # mode "position_error"), in master samples (1 ms each); mapping.delay_steps is the
    # master-to-slave half.
    delay_steps: int = _field(ForceFeedback.__init__, "delay_steps")
    # "none", or "tdpa": a time-domain passivity observer and controller at the master's
    # port (Hannaford & Ryu 2002) keeps the channel from giving the master more energy
    # than it took. Mode "force" needs the master's v_MS connected to it.
    passivity: str = _field(ForceFeedback.__init__, "passivity", choices=FEEDBACK_PASSIVITY)


@dc.dataclass
class LearningConfig:
    """What the HSMM (eqs. 4-11) learns from the demonstrations, and how it starts."""

    # Number of HSMM states N.
    num_states: int = _value(4, positive=True)
    # Positions of the observations [x, xdot, k]: "tool" (the measured tool point p_WE,
    # v_WE) or "reference" (the reference the CLIK received and its rate: what the slave
    # tracked with the gain k; a pen pressed into the sheet only shows in the reference).
    positions: str = _value("tool", choices=("tool", "reference"))
    # Initial states: "time" (equal times), "kmeans", "polyline" (straight pieces of the
    # path: states start where it turns).
    init: str = _field(HSMM.__init__, "init", choices=HSMM_INITS)
    # Covariance floor, relative to each dimension's variance in the data.
    reg_covar: float = _field(HSMM.__init__, "reg_covar", positive=True)
    # EM iterations at most.
    n_iter: int = _field(HSMM.__init__, "n_iter", positive=True)
    # Fit a task-parameterised HSMM (frames: robot base and scene; learning/tphsmm.py) even
    # when the demonstrations share one placement (it is fitted whenever they do not).
    task_parameterised: bool = _value(False)
    # The TP-HSMM's task frames: "scene" (the scene frame T alone) or "base_and_scene" (the
    # robot's base too, Calinon 2016's product of both). Measured (docs/placements.md): the
    # base frame pulls the drawing's strokes 8 mm towards where the sheet was on average
    # (its Gaussians are no wider than the covariance floor), the scene frame alone 0.5 mm.
    task_frames: str = _value("scene", choices=("scene", "base_and_scene"))


@dc.dataclass
class ReproductionConfig:
    """How the learnt task is reproduced (eqs. 12-18, 23; ``docs/reproduction.md``)."""

    # State weighting h_t: "temporal" (timing alone), "spatial" (eq. 14), "forward"
    # (eqs. 11, 13).
    weighting: str = _field(reproduce, "weighting", choices=WEIGHTINGS)
    # kappa of the cross-track attractor (1/s): a start offset decays as exp(-kappa t);
    # 0: eqs. 15-18 alone.
    restoring_gain: float = _field(reproduce, "restoring_gain")
    # The position the "gmr" reproducer observes: "reference" (its own x*) or "tool" (the
    # slave's measured tool point). The "lqr" tracker always re-plans from the tool point.
    observe: str = _value("reference", choices=("reference", "tool"))
    # "gmr": the paper's eqs. 15-18 (GMR velocity integrated by eq. 18; restoring_gain
    # applies to it); "lqr": a receding-horizon LQR tracking the HSMM's states, re-planned
    # from the measured tool point every step (docs/reproduction.md, Trackers), with the
    # temporal or forward weighting.
    tracker: str = _field(reproduce, "tracker", choices=TRACKERS)
    # LQR tracker: steps planned ahead, the control cost r (s^4/m^2), how far its plan may
    # lead the measured tool point (m), and whose precision costs a step: "active" (the
    # most probable state's) or "mixture" (weighted by h).
    horizon: int = _field(reproduce, "horizon", positive=True)
    control_cost: float = _field(reproduce, "control_cost", positive=True)
    max_lead: float = _field(HsmmLqrReproducer.__init__, "max_lead")
    state_cost: str = _field(reproduce, "state_cost", choices=STATE_COSTS)
    # K_ptr (N/m) and K_dtr (N s/m) of the tracking force (eq. 23; Table I: 50 and 50).
    tracking_gains: list[float] = _value([50.0, 50.0], size=2)
    # Simulated time to let the arm come to rest in the scene, holding x*_0, before the
    # reproduction starts (s).
    settle_time: float = _value(1.0)
    # Start offsets (m, in the scene frame T) of the extra reproductions that the full
    # demo runs, each from the demonstrations' mean start plus the offset.
    start_offsets: list[list[float]] = _value([], signed=True)


@dc.dataclass
class Scenario:
    """One run: task and scene, plant, devices, operator, EMG, controllers, learning."""

    # "cotter_pin" or "drawing".
    task: str = _value("cotter_pin", choices=TASKS)
    # Where the task's object stands and its physics.
    scene: SceneConfig = dc.field(default_factory=SceneConfig)
    # Override of the task's default plan (in the scene frame); leave out for the default.
    plan: typing.Optional[PlanConfig] = None
    # The plant (time step 1 ms: the PD and the master are tuned for it). Point contact:
    # the drawing's pen is tuned for it (hemg_drake.tasks.drawing says why). Live output
    # ports: the contact force a sensor reads is that of the step about to be taken, and
    # the plant steps by a plain discrete update instead of an unrestricted one; the
    # demonstration diagram runs 16-28 % faster (benchmarks/bench_demonstration.py).
    plant: MultibodyPlantConfig = dc.field(
        default_factory=lambda: MultibodyPlantConfig(
            time_step=1e-3, contact_model="point", use_sampled_output_ports=False
        )
    )
    # Drake's simulator settings (target_realtime_rate 0: as fast as possible).
    simulator: SimulatorConfig = dc.field(default_factory=SimulatorConfig)
    # Simulated length of one demonstration (s).
    duration: float = _value(8.0, positive=True, maximum=MAX_DURATION)
    # Sample period of the logged demonstration (s; Table I: 0.01).
    log_period: float = _value(0.01, positive=True)
    # Number of demonstrations C (cotter pin 4, drawing 3).
    num_demonstrations: int = _value(4, positive=True)
    # Demonstration c (1-based) is run with seed ``seed + c - 1``: plan variability, sEMG
    # noise; the HSMM's initialisation takes ``seed``.
    seed: int = _value(0)
    mapping: MappingConfig = dc.field(default_factory=MappingConfig)
    master: MasterConfig = dc.field(default_factory=MasterConfig)
    operator: OperatorConfig = dc.field(default_factory=OperatorConfig)
    emg: EmgConfig = dc.field(default_factory=EmgConfig)
    clik: ClikConfig = dc.field(default_factory=ClikConfig)
    feedback: FeedbackConfig = dc.field(default_factory=FeedbackConfig)
    learning: LearningConfig = dc.field(default_factory=LearningConfig)
    reproduction: ReproductionConfig = dc.field(default_factory=ReproductionConfig)

    def seeds(self):
        """Seeds of the C demonstrations: ``[seed, seed + 1, ..., seed + C - 1]``."""
        return [self.seed + c for c in range(self.num_demonstrations)]

    def X_WT(self):
        """The scene frame's pose in the world (``scene.position``, ``scene.yaw_deg``)."""
        position = self.scene.position or DEFAULT_POSITIONS[self.task]
        return scene_pose(position, self.scene.yaw_deg)

    def scene_params(self):
        """The task's scene parameters: ``scene.cotter_pin`` or ``scene.drawing``."""
        return getattr(self.scene, self.task)

    def task_plan(self):
        """The plan in force, in the world: the override or the task's default, placed."""
        X_WT = self.X_WT()
        if self.plan is not None:
            data = dc.asdict(self.plan)
            # Empty optional lists take TaskPlan's defaults.
            for name in ("pen_down", "effort"):
                if not data[name]:
                    del data[name]
            data["points"] = to_world(X_WT, data["points"]).tolist()
            return TaskPlan.from_dict(data)
        if self.task == "cotter_pin":
            return cotter_pin.default_cotter_pin_plan(X_WT=X_WT)
        return drawing.default_drawing_plan(self.scene.drawing, X_WT=X_WT)

    def R_WM(self):
        """The master frame's orientation in W: the scene's yaw, then ``mapping.rpy_deg``."""
        R_TM = RotationMatrix(RollPitchYaw(np.radians(self.mapping.rpy_deg)))
        return self.X_WT().rotation() @ R_TM

    def workspace_mapping(self):
        """The :class:`WorkspaceMapping` of the scenario, placed with the scene."""
        p_WMo = to_world(self.X_WT(), self.mapping.scene_offset)
        return WorkspaceMapping(scale=self.mapping.scale, R_WM=self.R_WM(), p_WMo=p_WMo)

    def to_yaml(self):
        """YAML text that :func:`parse_scenario` reads back to an equal scenario."""
        return yaml_dump_typed(self)

    def replaced(self, overrides=(), *, source="--set"):
        """A checked copy with dotted keys overridden, e.g. ``["duration=2.0"]``.

        Raises ValueError (naming ``source``, the override and the key) as
        :func:`load_scenario` does.
        """
        return parse_scenario(self.to_yaml(), source="the scenario", overrides=overrides,
                              overrides_source=source)  # fmt: skip


# Checks of Drake's config structs' fields, which carry no metadata of their own.
_STRUCT_CHECKS = {"plant.time_step": {"positive": True}}
# Sections whose dataclass checks itself (``check()``), by key path.
_SELF_CHECKED = ("scene.cotter_pin", "scene.drawing")


def load_scenario(path, *, overrides=()):
    """Read and check a scenario file, with optional ``key=value`` overrides.

    Parameters
    ----------
    path : path-like, a YAML file.
    overrides : sequence of str
        ``"dotted.key=value"`` with the value in YAML syntax (``--set`` on the CLI), applied
        in order on top of the file.

    Returns
    -------
    Scenario

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        A folder, an empty or non-UTF-8 file, malformed YAML, an unknown key, a value of
        the wrong type or size, a non-finite or negative number, an unknown task or method,
        a malformed override: the message names the file (or the override) and the key.
    """
    path = Path(path)
    text = read_yaml_text(path, kind="scenario")
    if not text.strip() or (_parses(text) and yaml_load(data=text) in (None, {})):
        # An empty file would silently run the default scenario.
        raise ValueError(f"{path}: the scenario file is empty; give at least its 'task'")
    return parse_scenario(text, source=str(path), overrides=overrides)


def shipped_scenario(name):
    """Path of a scenario shipped with the package: ``"cotter_pin"`` or ``"drawing"``."""
    path = SCENARIOS / f"{name}.yaml"
    if not path.is_file():
        raise FileNotFoundError(f"no shipped scenario named {name!r} (have {list(TASKS)})")
    return Path(str(path))


def _parses(text):
    try:
        yaml_load(data=text)
    except yaml.YAMLError:
        return False
    return True


def parse_scenario(text, *, source="<scenario>", overrides=(), overrides_source="--set"):
    """Like :func:`load_scenario`, from YAML text; ``source`` names it in errors.

    ``overrides_source`` names the overrides in their errors (``--set`` by default).
    """
    raw = _parse_yaml(text, source)
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ValueError(f"{source}: the top level must be a mapping of Scenario's fields")
    for override in overrides:
        where = f"{overrides_source} {override}"
        try:
            _apply_override(raw, override, where)
            check_types(raw, Scenario)
        except ValueError as error:
            raise ValueError(f"{where}: {first_line(error)}") from None
    try:
        check_types(raw, Scenario)
        data = yaml.safe_dump(raw, sort_keys=False)
        scenario = yaml_load_typed(schema=Scenario, data=data, defaults=Scenario())
        _check_values(scenario)
    except (RuntimeError, ValueError, AssertionError) as error:
        origin = _blame(first_line(error), source, overrides, overrides_source)
        raise ValueError(f"{origin}: {first_line(error)}") from None
    return scenario


def _blame(message, source, overrides, overrides_source):
    """Who a failed check is about: the override that set its key, else the source."""
    named = re.findall(r"key '([\w.]+)", message)
    for override in reversed(overrides):
        key = str(override).partition("=")[0].strip()
        if any(name == key or f"{name}.".startswith(f"{key}.") or key.startswith(f"{name}.")
               for name in named):  # fmt: skip
            return f"{overrides_source} {override}"
    return source


def _parse_yaml(text, source):
    try:
        return yaml_load(data=text) if text.strip() else {}
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(error, "problem", None) or first_line(error)
        raise ValueError(f"{source}: malformed YAML{where}: {problem}") from None


def _apply_override(raw, override, where):
    """Set ``key.path=value`` (YAML value) in the raw mapping ``raw``."""
    key, equals, value_text = str(override).partition("=")
    key = key.strip()
    if not equals or not key or any(not part for part in key.split(".")):
        raise ValueError("an override must read key=value, e.g. emg.k_max=150")
    if not value_text.strip():
        raise ValueError(f"an override needs a value after '=', e.g. {key}=...")
    value = _parse_yaml(value_text, "the value")
    node = raw
    *parents, leaf = key.split(".")
    for depth, name in enumerate(parents):
        child = node.get(name)
        if child is None:
            child = node[name] = {}
        if not isinstance(child, dict):
            path = ".".join(parents[: depth + 1])
            raise ValueError(f"key '{path}' holds a value, not a section: cannot set '{key}'")
        node = child
    node[leaf] = value


def _leaves(obj, key="", checks=None):
    """(key path, value, checks) of every value (number, string, list) in a loaded scenario."""
    if obj is None or isinstance(obj, (bool, str, int, float, list, np.ndarray)):
        yield key, obj, checks or _STRUCT_CHECKS.get(key, {})
    elif key in _SELF_CHECKED:
        try:
            obj.check()
        except ValueError as error:
            raise ValueError(f"key '{key}': {error}") from None
    else:
        metadata = {f.name: f.metadata for f in dc.fields(obj)} if dc.is_dataclass(obj) else {}
        for name in schema_fields(type(obj)):
            path = f"{key}.{name}" if key else name
            yield from _leaves(getattr(obj, name), path, metadata.get(name))


def _check_values(scenario):
    for key, value, checks in _leaves(scenario):
        choices = checks.get("choices")
        if choices is not None and value not in choices:
            raise ValueError(f"key '{key}' = {value!r} is not one of {tuple(choices)}")
        if isinstance(value, (bool, str)) or value is None:
            continue
        try:
            numbers = np.array(value, dtype=float)
        except ValueError:  # strings (plan.kinds), ragged lists: the TaskPlan checks them
            continue
        size = checks.get("size")
        sizes = size if isinstance(size, tuple) else (size,)
        if size is not None and not (numbers.ndim == 1 and len(numbers) in sizes):
            count = " or ".join(str(n) for n in sizes)
            raise ValueError(f"key '{key}' must hold {count} numbers, got {value!r}")
        if not np.all(np.isfinite(numbers)):
            raise ValueError(f"key '{key}' must be finite, got {value!r}")
        if checks.get("positive") and np.any(numbers <= 0):
            raise ValueError(f"key '{key}' must be positive, got {value!r}")
        if not checks.get("signed") and np.any(numbers < 0):
            raise ValueError(f"key '{key}' must not be negative, got {value!r}")
        maximum = checks.get("maximum")
        if maximum is not None and np.any(numbers > maximum):
            raise ValueError(f"key '{key}' must be at most {maximum:g}, got {value!r}")
        if checks.get("fraction") and np.any(numbers > 1):
            raise ValueError(f"key '{key}' must lie in [0, 1], got {value!r}")
    settings = scenario.reproduction
    if settings.tracker == "lqr" and settings.weighting == "spatial":
        raise ValueError(
            "key 'reproduction.weighting' = 'spatial' does not go with tracker 'lqr' (it "
            "tracks a state sequence: 'temporal' or 'forward')"
        )
    placements = scenario.scene.placements
    box = np.array(placements.position_range, dtype=float).reshape(-1, 3) if all(
        len(row) == 3 for row in placements.position_range
    ) else None  # fmt: skip
    if placements.position_range and (box is None or len(box) != 2 or np.any(box[0] > box[1])):
        raise ValueError(
            "key 'scene.placements.position_range' must be [[xmin, ymin, zmin], [xmax, ymax, "
            f"zmax]] with each min <= max, got {placements.position_range}"
        )
    yaws = placements.yaw_range_deg
    if yaws and yaws[0] > yaws[1]:
        raise ValueError(
            f"key 'scene.placements.yaw_range_deg' must be [smallest, largest], got {yaws}"
        )
    offsets = scenario.reproduction.start_offsets
    if any(len(offset) != 3 for offset in offsets):
        raise ValueError(f"key 'reproduction.start_offsets' must hold [dx, dy, dz] lists, got {offsets}")
    if scenario.plant.time_step > MAX_TIME_STEP:
        raise ValueError(
            f"key 'plant.time_step' must be at most {MAX_TIME_STEP} s (the PD and the master "
            f"are tuned for it), got {scenario.plant.time_step}"
        )
    calibration_samples = int(round(scenario.emg.calibration_duration * MYO_RATE))
    if calibration_samples < scenario.emg.window:
        raise ValueError(
            f"key 'emg.calibration_duration' gives {calibration_samples} samples, fewer than "
            f"the window 'emg.window' = {scenario.emg.window}: no envelope to calibrate"
        )
    if not scenario.emg.k_min < scenario.emg.k_max:
        raise ValueError(
            f"keys 'emg.k_min' < 'emg.k_max' required, got {scenario.emg.k_min}, "
            f"{scenario.emg.k_max}"
        )
    if scenario.log_period < scenario.plant.time_step or not math.isclose(
        scenario.log_period / scenario.plant.time_step,
        round(scenario.log_period / scenario.plant.time_step),
    ):
        raise ValueError(
            f"key 'log_period' must be a whole multiple of 'plant.time_step', got "
            f"{scenario.log_period}"
        )
    if scenario.plan is not None:
        try:
            scenario.task_plan()
        except ValueError as error:
            raise ValueError(f"key 'plan': {error}") from None
