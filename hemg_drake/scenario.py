"""Scenarios: everything a run depends on, as data: dataclasses read from YAML.

A scenario file is one YAML mapping whose keys are the fields of :class:`Scenario` (nested
sections for the sub-dataclasses); every key may be left out to take its default. Every
default exists once: each section is a system's own ``...Config`` dataclass, which lives
beside the system (``hemg_drake/<package>/config.py``) and owns its defaults, so
``Scenario()`` builds exactly the systems the library builds with its defaults. The plant and the simulator are configured
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

from hemg_drake.control.config import MAX_TIME_STEP, ClikConfig, PdConfig
from hemg_drake.config_fields import checked
from hemg_drake.emg.config import MYO_RATE, EmgConfig
from hemg_drake.fileio import read_yaml_text
from hemg_drake.learning.config import LearningConfig, ReproductionConfig
from hemg_drake.tasks import cotter_pin, drawing
from hemg_drake.tasks.config import PlanConfig, SceneConfig
from hemg_drake.tasks.placement import scene_pose, to_world
from hemg_drake.tasks.plan import TaskPlan
from hemg_drake.teleop.config import FeedbackConfig, MappingConfig, MasterConfig, OperatorConfig
from hemg_drake.teleop.mapping import WorkspaceMapping
from hemg_drake.yaml_schema import check_types, first_line, schema_fields

TASKS = ("cotter_pin", "drawing")
# Longest demonstration (s): 10 minutes of a 1 kHz diagram is minutes to simulate and about
# 0.5 GB of logs; a longer one is more likely a typo than a plan.
MAX_DURATION = 600.0
# Where each task's scene stands by default (scene frame T's origin, m, in W).
DEFAULT_POSITIONS = {"cotter_pin": cotter_pin.DEFAULT_POSITION, "drawing": drawing.DEFAULT_POSITION}
# The scenarios shipped with the package (hemg_drake/scenarios/<name>.yaml).
SCENARIOS = importlib.resources.files("hemg_drake") / "scenarios"


@dc.dataclass
class Scenario:
    """One run: task and scene, plant, devices, operator, EMG, controllers, learning."""

    # "cotter_pin" or "drawing".
    task: str = checked("cotter_pin", choices=TASKS)
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
    duration: float = checked(8.0, positive=True, maximum=MAX_DURATION)
    # Sample period of the logged demonstration (s; Table I: 0.01).
    log_period: float = checked(0.01, positive=True)
    # Number of demonstrations C (cotter pin 4, drawing 3).
    num_demonstrations: int = checked(4, positive=True)
    # Demonstration c (1-based) is run with seed ``seed + c - 1``: plan variability, sEMG
    # noise; the HSMM's initialisation takes ``seed``.
    seed: int = checked(0)
    mapping: MappingConfig = dc.field(default_factory=MappingConfig)
    master: MasterConfig = dc.field(default_factory=MasterConfig)
    operator: OperatorConfig = dc.field(default_factory=OperatorConfig)
    emg: EmgConfig = dc.field(default_factory=EmgConfig)
    clik: ClikConfig = dc.field(default_factory=ClikConfig)
    pd: PdConfig = dc.field(default_factory=PdConfig)
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
