"""Scenarios: everything a demonstration run needs, as dataclasses read from YAML.

A scenario file is one YAML mapping whose keys are the fields of :class:`Scenario` (nested
sections for the sub-dataclasses); every key may be left out to take its default. It is read
with Drake's ``yaml_load_typed``; :func:`load_scenario` adds what that does not check (the
YAML key path of a wrongly typed value, vector sizes, finite and non-negative numbers, the
task name) and reports every problem as one ``ValueError`` naming the file and the key::

    scenario = load_scenario("scenarios/cotter_pin.yaml")
    plan = scenario.task_plan()

The plant's settings are Drake's own ``MultibodyPlantConfig`` (key ``plant``).
"""

import dataclasses as dc
import math
import typing
from pathlib import Path

import numpy as np
import yaml
from pydrake.common.yaml import yaml_dump_typed, yaml_load, yaml_load_typed
from pydrake.math import RollPitchYaw, RotationMatrix
from pydrake.multibody.plant import MultibodyPlantConfig

from hemg_drake.control.clik import CLIK_METHODS
from hemg_drake.control.pd import MAX_TIME_STEP
from hemg_drake.emg.sources import MYO_RATE
from hemg_drake.tasks.cotter_pin import default_cotter_pin_plan
from hemg_drake.tasks.drawing import default_drawing_plan
from hemg_drake.tasks.plan import TaskPlan
from hemg_drake.teleop.feedback import MODES as FEEDBACK_MODES

# Each task's default plan, used when a scenario gives none.
DEFAULT_PLANS = {"cotter_pin": default_cotter_pin_plan, "drawing": default_drawing_plan}
TASKS = tuple(DEFAULT_PLANS)


@dc.dataclass
class PlanConfig:
    """A task plan written out in the scenario (see :class:`~hemg_drake.tasks.plan.TaskPlan`)."""

    # Waypoint times (s), strictly increasing, at least two.
    times: list[float] = dc.field(default_factory=list)
    # Waypoints p_WE of the tool point in the world frame (m), one [x, y, z] per time.
    points: list[list[float]] = dc.field(default_factory=list)
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
    scale: float = 2.0
    # p_WMo: the slave point (world, m) that the centre of the master's workspace maps to.
    offset: list[float] = dc.field(default_factory=lambda: [0.64, -0.84, 0.12])
    # Orientation R_WM of the master frame M in the world, roll-pitch-yaw in degrees. The
    # default puts the operator behind the robot, facing the way it faces.
    rpy_deg: list[float] = dc.field(default_factory=lambda: [90.0, 0.0, -90.0])
    # Constant transport delay of the teleoperation channel, in master samples (1 ms each).
    delay_steps: int = 0


@dc.dataclass
class MasterConfig:
    """Touch X tip dynamics (:class:`~hemg_drake.teleop.master.HapticMaster`), SI units."""

    # Apparent mass at the tip (kg).
    mass: float = 0.045
    # Viscous backdrive damping (N s/m).
    damping: float = 0.1
    # Coulomb backdrive friction (N).
    friction: float = 0.0
    # Motor force saturation (N), the Touch X peak force.
    peak_force: float = 7.9
    # Workspace box, width x height x depth (m).
    workspace_size: list[float] = dc.field(default_factory=lambda: [0.16, 0.12, 0.12])
    # Soft walls beyond the box: spring (N/m) and damper (N s/m).
    wall_stiffness: float = 5000.0
    wall_damping: float = 20.0
    # Sample period of the haptic loop (s): the device's servo rate, 1 kHz.
    period: float = 1e-3


@dc.dataclass
class OperatorConfig:
    """The simulated operator (:class:`~hemg_drake.teleop.operator.SimulatedOperator`) and
    its seeded variability between demonstrations."""

    # Hand impedance pushing the stylus toward the planned point, in the master frame:
    # stiffness (N/m), damping (N s/m), and the saturation of the hand force's norm (N).
    hand_stiffness: float = 300.0
    hand_damping: float = 5.0
    max_hand_force: float = 15.0
    # Muscle activation in [0, 1]: relaxed, moving freely, working against the task (at
    # effort 1).
    rest_activation: float = 0.05
    free_activation: float = 0.2
    forceful_activation: float = 0.7
    # Co-contraction: activation added per newton of force felt on the stylus (1/N).
    co_contraction_gain: float = 0.05
    # Time constant of the muscle activation (s).
    activation_time_constant: float = 0.04
    # Sample period of the activation (s): the MYO's 1/200 s, the rate at which the sEMG
    # source reads it (a faster update would be computed and never seen).
    period: float = 0.005
    # Variability (TaskPlan.perturbed): log-normal spread of each segment's duration, the
    # path offset's standard deviation per world axis (m), log-normal spread of the effort.
    timing_std: float = 0.1
    path_std: list[float] = dc.field(default_factory=lambda: [0.003, 0.003, 0.003])
    effort_std: float = 0.1

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
    window: int = 20
    # RMS per channel, then summed, instead of the paper's RMS of the channel sum.
    per_channel: bool = False
    # Shape factor of the activation curve (Table I).
    A_emg: float = -0.6981
    # Gain K at rest and at maximum contraction (VariableGainPd's K; its tested range is
    # 5 to 500, Table I's 50 sits between).
    k_min: float = 10.0
    k_max: float = 200.0
    # Length of the synthetic rest and maximum-contraction recordings (s) from which the
    # envelope's calibration is computed before each demonstration.
    calibration_duration: float = 2.0


@dc.dataclass
class ClikConfig:
    """Closed-loop inverse kinematics (:class:`~hemg_drake.control.clik.Clik`, eq. 21)."""

    # K_sp: 1/(m^2 s) for "transpose", 1/s for "dls".
    gain: float = 300.0
    # "transpose" (the paper's J^T law) or "dls" (damped least squares).
    method: str = "transpose"
    # Damping of the "dls" law (m).
    damping: float = 0.05
    # Update period (s).
    period: float = 1e-3


@dc.dataclass
class FeedbackConfig:
    """Force fed back to the master (:class:`~hemg_drake.teleop.feedback.ForceFeedback`)."""

    # "force": the slave's interaction force; "position_error": the master PD of Table I.
    mode: str = "force"
    # Extra scale on the force in mode "force" (dimensionless).
    gain: float = 1.0
    # K_pm (N/m) and K_dm (N s/m) in mode "position_error" (Table I: 50 and 50).
    stiffness: float = 50.0
    damping: float = 50.0
    # Saturation of the motor force (N).
    peak_force: float = 7.9


@dc.dataclass
class Scenario:
    """One demonstration scenario: task, plant, devices, operator, EMG and controllers."""

    # "cotter_pin" or "drawing".
    task: str = "cotter_pin"
    # Override of the task's default plan; leave out for the default.
    plan: typing.Optional[PlanConfig] = None
    # The plant (time step 1 ms: the PD and the master are tuned for it; contact model).
    # Live output ports: the contact force a sensor reads is that of the step about to be
    # taken, not the last one's, and the plant steps by a plain discrete update instead of
    # an unrestricted one that copies its sampled outputs; the demonstration diagram runs
    # 16-28 % faster (benchmarks/bench_demonstration.py).
    plant: MultibodyPlantConfig = dc.field(
        default_factory=lambda: MultibodyPlantConfig(
            time_step=1e-3, use_sampled_output_ports=False
        )
    )
    # Simulated length of one demonstration (s).
    duration: float = 8.0
    # Sample period of the logged demonstration (s; Table I: 0.01).
    log_period: float = 0.01
    # Number of demonstrations C (cotter pin 4, drawing 3).
    num_demonstrations: int = 4
    # Number of HSMM states N for learning (cotter pin 4, drawing 18).
    num_states: int = 4
    # Demonstration c (0-based) is run with seed ``seed + c``: plan variability, sEMG noise.
    seed: int = 0
    mapping: MappingConfig = dc.field(default_factory=MappingConfig)
    master: MasterConfig = dc.field(default_factory=MasterConfig)
    operator: OperatorConfig = dc.field(default_factory=OperatorConfig)
    emg: EmgConfig = dc.field(default_factory=EmgConfig)
    clik: ClikConfig = dc.field(default_factory=ClikConfig)
    feedback: FeedbackConfig = dc.field(default_factory=FeedbackConfig)

    def seeds(self):
        """Seeds of the C demonstrations: ``[seed, seed + 1, ..., seed + C - 1]``."""
        return [self.seed + c for c in range(self.num_demonstrations)]

    def task_plan(self):
        """The plan in force: the override, or the task's default plan."""
        if self.plan is not None:
            data = dc.asdict(self.plan)
            # Empty optional lists take TaskPlan's defaults.
            for name in ("pen_down", "effort"):
                if not data[name]:
                    del data[name]
            return TaskPlan.from_dict(data)
        return DEFAULT_PLANS[self.task]()

    def R_WM(self):
        """The mapping's rotation as a ``RotationMatrix``."""
        return RotationMatrix(RollPitchYaw(np.radians(self.mapping.rpy_deg)))

    def to_yaml(self):
        """YAML text that :func:`parse_scenario` reads back to an equal scenario."""
        return yaml_dump_typed(self)

    def replaced(self, *, source="<overrides>", **changes):
        """A checked copy with top-level fields changed, e.g. ``replaced(duration=2.0)``.

        Raises ValueError (naming ``source`` and the key) as :func:`load_scenario` does.
        """
        return parse_scenario(dc.replace(self, **changes).to_yaml(), source=source)


# Numbers that may be negative (all others must be >= 0), by YAML key path.
_SIGNED = {"plan.points", "mapping.offset", "mapping.rpy_deg", "emg.A_emg"}
# Numbers that must be strictly positive.
_POSITIVE = {
    "plant.time_step", "duration", "log_period", "num_demonstrations", "num_states",
    "mapping.scale", "master.mass", "master.workspace_size", "master.period",
    "operator.hand_stiffness",
    "operator.activation_time_constant", "operator.period", "emg.window",
    "emg.calibration_duration", "clik.gain", "clik.period",
}
# Vectors of fixed length.
_SIZES = {
    "mapping.offset": 3, "mapping.rpy_deg": 3, "master.workspace_size": 3,
    "operator.path_std": 3,
}
# Values in [0, 1].
_FRACTIONS = {
    "operator.rest_activation", "operator.free_activation", "operator.forceful_activation",
}
_CHOICES = {
    "task": TASKS,
    "clik.method": CLIK_METHODS,
    "feedback.mode": FEEDBACK_MODES,
}


def load_scenario(path):
    """Read and check a scenario file.

    Parameters
    ----------
    path : path-like, a YAML file.

    Returns
    -------
    Scenario

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Malformed YAML, an unknown key, a value of the wrong type or size, a non-finite or
        negative number, an unknown task or method: the message names the file and the key.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"scenario file not found: {path}")
    return parse_scenario(path.read_text(encoding="utf-8"), source=str(path))


def parse_scenario(text, *, source="<scenario>"):
    """Like :func:`load_scenario`, from YAML text; ``source`` names it in errors."""
    try:
        raw = yaml_load(data=text) if text.strip() else {}
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(error, "problem", None) or _first_line(error)
        raise ValueError(f"{source}: malformed YAML{where}: {problem}") from None
    if raw is None:
        raw = {}
    try:
        _check_types(raw, Scenario, "")
        scenario = yaml_load_typed(schema=Scenario, data=text) if raw else Scenario()
        _check_values(scenario)
    except (RuntimeError, ValueError, AssertionError) as error:
        raise ValueError(f"{source}: {_first_line(error)}") from None
    return scenario


def _first_line(error):
    return (str(error).strip().splitlines() or [type(error).__name__])[0]


def _fields(schema):
    """(name, type) of a dataclass's or a Drake config struct's fields."""
    if dc.is_dataclass(schema):
        hints = typing.get_type_hints(schema)
        return {f.name: hints[f.name] for f in dc.fields(schema)}
    return {f.name: f.type for f in schema.__fields__}


_TYPE_NAMES = {float: "a number", int: "an integer", bool: "true or false", str: "a string"}


def _check_types(value, schema, key):
    """Check raw YAML data against ``schema``, naming the key path of the first mismatch."""
    where = f"key '{key}'" if key else "the top level"
    origin, args = typing.get_origin(schema), typing.get_args(schema)
    if origin is typing.Union:  # Optional[X]
        if value is not None:
            _check_types(value, next(a for a in args if a is not type(None)), key)
    elif origin is list:
        if not isinstance(value, list):
            raise ValueError(f"{where} must be a list, got {value!r}")
        for i, item in enumerate(value):
            _check_types(item, args[0], f"{key}[{i}]")
    elif schema in (float, int, bool, str):
        ok = {
            float: isinstance(value, (int, float)) and not isinstance(value, bool),
            int: isinstance(value, int) and not isinstance(value, bool),
            bool: isinstance(value, bool),
            str: isinstance(value, str),
        }[schema]
        if not ok:
            raise ValueError(f"{where} must be {_TYPE_NAMES[schema]}, got {value!r}")
    else:
        if not isinstance(value, dict):
            raise ValueError(
                f"{where} must be a mapping of {schema.__name__}'s fields, got {value!r}"
            )
        fields = _fields(schema)
        unknown = sorted(set(value) - set(fields))
        if unknown:
            prefix = f"{key}." if key else ""
            raise ValueError(
                f"unknown key(s) {[prefix + str(u) for u in unknown]}; "
                f"{schema.__name__} has {sorted(fields)}"
            )
        for name, item in value.items():
            _check_types(item, fields[name], f"{key}.{name}" if key else name)


def _leaves(obj, key=""):
    """(key path, value) of every value (number, string, list) in a loaded scenario."""
    if obj is None or isinstance(obj, (bool, str, int, float, list)):
        yield key, obj
    else:
        for name in _fields(type(obj)):
            yield from _leaves(getattr(obj, name), f"{key}.{name}" if key else name)


def _check_values(scenario):
    for key, value in _leaves(scenario):
        if key in _CHOICES and value not in _CHOICES[key]:
            raise ValueError(f"key '{key}' = {value!r} is not one of {_CHOICES[key]}")
        if isinstance(value, (bool, str)) or value is None:
            continue
        try:
            numbers = np.array(value, dtype=float)
        except ValueError:  # strings (plan.kinds), ragged lists: the TaskPlan checks them
            continue
        if key in _SIZES and numbers.shape != (_SIZES[key],):
            raise ValueError(f"key '{key}' must hold {_SIZES[key]} numbers, got {value!r}")
        if not np.all(np.isfinite(numbers)):
            raise ValueError(f"key '{key}' must be finite, got {value!r}")
        if key not in _SIGNED and np.any(numbers < 0):
            raise ValueError(f"key '{key}' must not be negative, got {value!r}")
        if key in _POSITIVE and np.any(numbers <= 0):
            raise ValueError(f"key '{key}' must be positive, got {value!r}")
        if key in _FRACTIONS and np.any(numbers > 1):
            raise ValueError(f"key '{key}' must lie in [0, 1], got {value!r}")
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
