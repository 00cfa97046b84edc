"""Scenarios: everything a run depends on, as data: dataclasses read from YAML.

A scenario file is one YAML mapping whose keys are the fields of :class:`Scenario` (nested
sections for the sub-dataclasses); every key may be left out to take its default. Every
default exists once: each section is a system's own ``...Config`` dataclass, which lives
beside the system (``hemg_drake/<package>/config.py``) and owns its defaults and its range
checks. The plant and the simulator are configured by Drake's own ``MultibodyPlantConfig``
and ``SimulatorConfig``; the scene's physics by ``CotterPinParams`` and ``DrawingParams``.
This module imports those configs only: loading a scenario imports no system.

It is read as Drake's ``hardware_sim`` reads its scenarios: ``yaml_load_typed`` layers the
file and then each override on top of the defaults (``defaults=``). Before each layer,
:func:`~hemg_drake.yaml_schema.check_types` names the key path of an unknown key or a
wrongly typed value (Drake's own messages name neither); after the last,
:func:`~hemg_drake.config_fields.check_config` checks every value against its field's
range and each config's rules (``check(key)``). Every problem is one ``ValueError`` naming
the file (or the override) and the key. Any key can be overridden with
``overrides=["emg.k_max=150", "scene.position=[0.65, -0.80, 0.12]"]`` (YAML value syntax;
the CLI's ``--set``)::

    scenario = load_scenario(shipped_scenario("cotter_pin"), overrides=["scene.yaw_deg=20"])
    plan = scenario.task_plan()          # in the world, where the scene stands
"""

import copy
import dataclasses as dc
import functools
import importlib.resources
import math
import re
import typing
from pathlib import Path

import yaml
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.analysis import GetIntegrationSchemes, SimulatorConfig
from pydrake.visualization import VisualizationConfig

from hemg_drake.assist.config import AssistConfig
from hemg_drake.config_fields import check_config, checked
from hemg_drake.control.config import MAX_TIME_STEP, ClikConfig, PdConfig
from hemg_drake.emg.config import EmgConfig
from hemg_drake.fileio import read_yaml_text
from hemg_drake.learning.config import LearningConfig, ReproductionConfig
from hemg_drake.tasks import plans
from hemg_drake.tasks.config import PlanConfig, SceneConfig
from hemg_drake.tasks.placement import master_orientation, task_scene_pose, to_world
from hemg_drake.teleop.config import FeedbackConfig, MappingConfig, MasterConfig, OperatorConfig
from hemg_drake.yaml_schema import (
    check_types, first_line, override_data, parse_yaml, schema_fields,
)  # fmt: skip

TASKS = ("cotter_pin", "drawing")
# The largest seed: Drake's RandomGenerator takes a 32-bit seed (2**32 draws what 0 draws,
# measured), and demonstration c runs with seed + c - 1.
MAX_SEED = 2**32 - 1
# Strings of Drake's config structs that Drake does not check against a list: any bus name
# (the Visualization maps it to Drake's null bus, hemg_drake.diagrams.visualization).
FREE_STRINGS = ("visualization.lcm_bus",)
# Longest demonstration (s): 10 minutes of a 1 kHz diagram is minutes to simulate and about
# 0.5 GB of logs; a longer one is more likely a typo than a plan.
MAX_DURATION = 600.0
# Most demonstrations C: the paper takes 3 and 4. A simulated second costs about 0.6 s of CPU
# (measured on the cotter pin), so 100 demonstrations of the shipped 4.5 s take about 5 min
# and of the longest 600 s about 10 h: more is a typo, not a plan.
MAX_DEMONSTRATIONS = 100
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
    # Drake's visualisation settings, applied (ApplyVisualizationConfig) when a diagram is
    # built with a Visualization (hemg_drake.diagrams.visualization): the arm and its scene
    # in Meshcat at 32 frames/s (the replays' rate), nothing else. LCM goes to Drake's null
    # bus (no network traffic); Meshcat is always the Visualization's own, on the loopback
    # interface, so enable_meshcat_creation (Drake's server on every interface) must stay false.
    visualization: VisualizationConfig = dc.field(
        default_factory=lambda: VisualizationConfig(
            publish_period=1 / 32, publish_proximity=False, publish_contacts=False,
            publish_inertia=False, enable_meshcat_creation=False,
        )  # fmt: skip
    )
    # Simulated length of one demonstration (s).
    duration: float = checked(8.0, positive=True, maximum=MAX_DURATION)
    # Sample period of the logged demonstration (s; Table I: 0.01).
    log_period: float = checked(0.01, positive=True)
    # Number of demonstrations C (cotter pin 4, drawing 3).
    num_demonstrations: int = checked(4, positive=True, maximum=MAX_DEMONSTRATIONS)
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
    # Shared control while teleoperating (docs/shared_control.md); mode none: none.
    assist: AssistConfig = dc.field(default_factory=AssistConfig)

    def seeds(self):
        """Seeds of the C demonstrations: ``[seed, seed + 1, ..., seed + C - 1]``."""
        return [self.seed + c for c in range(self.num_demonstrations)]

    def X_WT(self):
        """The scene frame's pose in the world (``scene.position``, ``scene.yaw_deg``)."""
        return task_scene_pose(self.task, self.scene)

    def scene_params(self):
        """The task's scene parameters: ``scene.cotter_pin`` or ``scene.drawing``."""
        return getattr(self.scene, self.task)

    def task_plan(self):
        """The plan in force, in the world: ``plan`` or the task's default, placed."""
        return plans.task_plan(self.task, self.scene, self.plan)

    def R_WM(self):
        """The master frame's orientation in W: the scene's yaw, then ``mapping.rpy_deg``."""
        return master_orientation(self.X_WT(), self.mapping.rpy_deg)

    def workspace_mapping(self):
        """The :class:`~hemg_drake.teleop.mapping.WorkspaceMapping`, placed with the scene."""
        # Imported here: teleop.mapping defines systems, which loading a scenario must not.
        from hemg_drake.teleop.mapping import WorkspaceMapping

        p_WMo = to_world(self.X_WT(), self.mapping.scene_offset)
        return WorkspaceMapping(scale=self.mapping.scale, R_WM=self.R_WM(), p_WMo=p_WMo)

    def check(self, key=""):
        """The rules that span sections or need a model (each section checks its own): the
        strings of Drake's config structs among the values Drake accepts
        (:func:`drake_choices`), point contact for the drawing, a plant step of at most
        ``MAX_TIME_STEP``, a log period that is a whole number of plant steps, a pin detent
        shorter than the pin, seeds within Drake's 32 bits. Raises ValueError naming the
        key."""
        for path, choices in drake_choices().items():
            section, name = path.split(".")
            value = getattr(getattr(self, section), name)
            if value not in choices:
                raise ValueError(f"key '{path}' = {value!r} is not one of {choices} (Drake's)")
        if self.task == "drawing" and self.plant.contact_model != "point":
            raise ValueError(
                f"key 'plant.contact_model' = {self.plant.contact_model!r} does not go with "
                "'task' = 'drawing': the drawing scene needs point contact (the pen is tuned "
                "for it; hemg_drake.tasks.drawing says why)"
            )
        last_seed = self.seed + self.num_demonstrations - 1
        if last_seed > MAX_SEED:
            raise ValueError(
                f"key 'seed' = {self.seed} with 'num_demonstrations' = "
                f"{self.num_demonstrations} seeds up to {last_seed}; Drake's random generator "
                f"takes seeds up to {MAX_SEED} (2**32 - 1)"
            )
        fresh = self.reproduction
        if fresh.num_heldout:
            last = fresh.heldout_seed + fresh.num_heldout - 1
            if fresh.heldout_seed <= self.seeds()[-1] and last >= self.seed or last > MAX_SEED:
                raise ValueError(
                    f"key 'reproduction.heldout_seed' = {fresh.heldout_seed} with "
                    f"'reproduction.num_heldout' = {fresh.num_heldout} takes seeds up to {last}: "
                    f"they must be disjoint from the training seeds {self.seed}-"
                    f"{self.seeds()[-1]} and at most {MAX_SEED}"
                )
        time_step = self.plant.time_step
        if not 0 < time_step <= MAX_TIME_STEP:
            raise ValueError(
                f"key 'plant.time_step' must be positive and at most {MAX_TIME_STEP} s (the "
                f"PD and the master are tuned for it), got {time_step}"
            )
        detent_length = self.scene.cotter_pin.detent_length
        if detent_length >= plans.pin_length():
            raise ValueError(
                f"key 'scene.cotter_pin.detent_length' must be shorter than the pin "
                f"({plans.pin_length()} m, its model's), got {detent_length}"
            )
        if not self.visualization.publish_period > 0:
            raise ValueError(
                "key 'visualization.publish_period' must be positive, got "
                f"{self.visualization.publish_period}"
            )
        if self.visualization.enable_meshcat_creation:
            raise ValueError(
                "key 'visualization.enable_meshcat_creation' must be false: Drake's own Meshcat "
                "listens on every interface; a diagram is shown in the loopback Meshcat of a "
                "Visualization (hemg_drake.diagrams.visualization)"
            )
        steps = self.log_period / time_step
        if steps < 1 or not math.isclose(steps, round(steps)):
            raise ValueError(
                f"key 'log_period' must be a whole multiple of 'plant.time_step', got "
                f"{self.log_period}"
            )
        self._check_assist()

    def _check_assist(self):
        """The assist's rules across sections: a model when it is on; guidance only through
        the force feedback and its passivity controller (an active port kept passive)."""
        assist = self.assist
        if (assist.mode != "none" or assist.gap_duration > 0) and not assist.model:
            raise ValueError(
                f"key 'assist.model' must name a fitted model file (hemg-drake learn's "
                f"model.npz) when 'assist.mode' = {assist.mode!r} or 'assist.gap_duration' "
                f"= {assist.gap_duration} > 0"
            )
        if assist.guidance_stiffness > 0 and (
            self.feedback.mode != "force" or self.feedback.passivity != "tdpa"
        ):
            raise ValueError(
                f"key 'assist.guidance_stiffness' = {assist.guidance_stiffness} needs "
                "'feedback.mode' = 'force' and 'feedback.passivity' = 'tdpa' (the guidance is "
                f"fed back with the contact force; got {self.feedback.mode!r} and "
                f"{self.feedback.passivity!r})"
            )

    def to_yaml(self):
        """YAML text that :func:`parse_scenario` reads back to an equal scenario."""
        return yaml_dump_typed(self)

    def replaced(self, overrides=(), *, source="--set"):
        """A checked copy with dotted keys overridden, e.g. ``["duration=2.0"]``.

        Raises ValueError (naming ``source``, the override and the key) as
        :func:`load_scenario` does.
        """
        return _layered(copy.deepcopy(self), [], overrides, source="the scenario",
                        overrides_source=source)  # fmt: skip


@functools.cache
def drake_choices():
    """The strings Drake accepts in each string field of the scenario's Drake config
    structs, asked of Drake: ``{"plant.contact_model": ("point", ...), ...}``.

    ``simulator.integration_scheme``: ``GetIntegrationSchemes()``. The plant's strings
    (``contact_model``, ``discrete_contact_approximation``,
    ``contact_surface_representation``): the list that each field's documentation in
    pydrake gives ("Valid strings are: ..."), since Drake binds no function that lists
    them. The strings of ``FREE_STRINGS`` take any value.
    """
    choices = {"simulator.integration_scheme": tuple(GetIntegrationSchemes())}
    for field in MultibodyPlantConfig.__fields__:
        if field.type is str:
            doc = getattr(MultibodyPlantConfig, field.name).__doc__ or ""
            items = re.match(r'(\s*-\s*"\w+")*', doc.partition("Valid strings are:")[2])
            choices[f"plant.{field.name}"] = tuple(re.findall(r'"(\w+)"', items.group()))
    return choices


def check_overrides_read(overrides, reads, *, reader, source="--set"):
    """Refuse an override of a key that ``reader`` does not read, in one line.

    Parameters
    ----------
    overrides : sequence of str, ``key=value`` as for :func:`load_scenario`.
    reads : sequence of str, the key paths ``reader`` reads: a section (``"learning"``: every
        key under it) or a key (``"seed"``).
    reader : str, who reads them, e.g. ``"learn"``.

    Raises
    ------
    ValueError
        ``--set emg.k_max=150: learn does not use emg.*: it reads learning.* and seed``; an
        override of ``task``: the task of a run folder is fixed. A malformed override is
        left for :func:`load_scenario` to name.
    """
    shown = [key if _leaf(key) else f"{key}.*" for key in reads]
    said = ", ".join(shown[:-1]) + f" and {shown[-1]}" if len(shown) > 1 else shown[0]
    for override in overrides:
        try:
            keys = _key_paths(override_data(override, Scenario))
        except ValueError:
            continue
        for key in keys:
            if key == "task":
                raise ValueError(
                    f"{source} {override}: the task of a run folder is fixed (its dataset's); "
                    "demonstrate the other task into a folder of its own"
                )
            if not any(key == read or key.startswith(f"{read}.") for read in reads):
                section = key.split(".")[0]
                partly = _leaf(section) or any(r.split(".")[0] == section for r in reads)
                unused = key if partly else f"{section}.*"
                raise ValueError(f"{source} {override}: {reader} does not use {unused}: it "
                                 f"reads {said}")  # fmt: skip


def _key_paths(data, path=""):
    """The dotted key paths of the values in nested mappings ``data``."""
    if not isinstance(data, dict) or not data:
        return [path]
    return [key for name, value in data.items()
            for key in _key_paths(value, f"{path}.{name}" if path else str(name))]  # fmt: skip


def _leaf(key):
    """True if ``key`` (a dotted path in Scenario) holds a value, not a section."""
    schema = Scenario
    for name in key.split("."):
        fields = schema_fields(schema)
        if name not in fields:
            return True
        schema = fields[name]
        if typing.get_origin(schema) is typing.Union:
            schema = next(a for a in typing.get_args(schema) if a is not type(None))
    return not (dc.is_dataclass(schema) or hasattr(schema, "__fields__"))


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
    if parse_yaml(text, str(path)) in (None, {}):
        # An empty file would silently run the default scenario.
        raise ValueError(f"{path}: the scenario file is empty; give at least its 'task'")
    return parse_scenario(text, source=str(path), overrides=overrides)


def shipped_scenario(name):
    """Path of a scenario shipped with the package: ``"cotter_pin"`` or ``"drawing"``."""
    path = SCENARIOS / f"{name}.yaml"
    if not path.is_file():
        raise FileNotFoundError(f"no shipped scenario named {name!r} (have {list(TASKS)})")
    return Path(str(path))


def parse_scenario(text, *, source="<scenario>", overrides=(), overrides_source="--set"):
    """Like :func:`load_scenario`, from YAML text; ``source`` names it in errors.

    ``overrides_source`` names the overrides in their errors (``--set`` by default).
    """
    data = parse_yaml(text, source)
    if data is not None and not isinstance(data, dict):
        raise ValueError(f"{source}: the top level must be a mapping of Scenario's fields")
    layers = [(source, data)] if data else []
    return _layered(Scenario(), layers, overrides, source=source,
                    overrides_source=overrides_source)  # fmt: skip


def _layered(scenario, layers, overrides, *, source, overrides_source):
    """``scenario`` with the data ``layers`` ((origin, data) pairs) and then ``overrides``
    loaded on top, in order, as ``yaml_load_typed(defaults=...)`` layers; then checked."""
    layers = list(layers)
    for override in overrides:
        origin = f"{overrides_source} {override}"
        try:
            layers.append((origin, override_data(override, Scenario)))
        except ValueError as error:
            raise ValueError(f"{origin}: {first_line(error)}") from None
    for origin, data in layers:
        try:
            check_types(data, Scenario)  # names the key path: Drake's messages do not
            text = yaml.safe_dump(data, sort_keys=False)
            scenario = yaml_load_typed(schema=Scenario, data=text, defaults=scenario)
        except (RuntimeError, ValueError, AssertionError) as error:
            raise ValueError(f"{origin}: {first_line(error)}") from None
    try:
        check_config(scenario)
    except ValueError as error:
        origin = _blame(first_line(error), source, overrides, overrides_source)
        raise ValueError(f"{origin}: {first_line(error)}") from None
    return scenario


def _blame(message, source, overrides, overrides_source):
    """Who a failed check is about: the last override that set its key, else the source."""
    named = re.findall(r"'([\w.]+)'", message)  # every quoted key path (and value)
    for override in reversed(overrides):
        key = str(override).partition("=")[0].strip()
        if any(name == key or f"{name}.".startswith(f"{key}.") or key.startswith(f"{name}.")
               for name in named):  # fmt: skip
            return f"{overrides_source} {override}"
    return source
