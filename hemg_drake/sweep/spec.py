"""A sweep file: its fields (:class:`SweepSpec`), their checks, and the trials it names."""

import dataclasses as dc
import hashlib
import importlib.resources
import itertools
from pathlib import Path

import yaml

from hemg_drake.fileio import read_yaml_text
from hemg_drake.yaml_schema import check_types, first_line, parse_yaml

STEPS = ("demonstrate", "learn", "reproduce", "heldout")
DESIGNS = ("grid", "one_at_a_time")
# The sweeps shipped with the package (hemg_drake/sweeps/<name>.yaml): the studies.
SWEEPS = importlib.resources.files("hemg_drake") / "sweeps"
DEFAULT_METRICS = (
    "reproduction.position_rmse_m",
    "reproduction.spatial_position_rmse_m",
    "reproduction.success",
)


@dc.dataclass
class Axis:
    """One varied setting of a sweep."""

    # Column name in the table and label in the figure; default: the first key.
    name: str = ""
    # Scenario keys (dotted) that each value sets, all to that value; default: [name].
    keys: list[str] = dc.field(default_factory=list)
    # The values, any YAML (numbers, strings, lists); read as YAML text.
    values: list[str] = dc.field(default_factory=list)
    # Instead of values: named cases, each a list of overrides ``key=value``.
    cases: dict[str, list[str]] = dc.field(default_factory=dict)
    # True: the overrides apply to the reproduction only (step reproduce), not to the
    # demonstrations nor the learning: the world changed after the demonstrations (a moved
    # sheet, a block, a push). The trials of its values share their demonstrations.
    reproduce_only: bool = False


@dc.dataclass
class SweepSpec:
    """A sweep file (see the module docstring)."""

    # A scenario file (relative to the sweep file) or a shipped scenario's name.
    scenario: str = ""
    # Overrides of every trial, ``key=value`` (YAML value syntax, as ``--set``).
    set: list[str] = dc.field(default_factory=list)
    # The varied settings.
    axes: list[Axis] = dc.field(default_factory=list)
    # "grid": every combination of the axes' values; "one_at_a_time": each axis varied
    # alone, the others at the base scenario.
    design: str = "grid"
    # Values of the scenario key ``seed`` (demonstration c runs with seed + c - 1: space
    # them by more than the number of demonstrations for independent trials).
    seeds: list[int] = dc.field(default_factory=lambda: [0])
    # Steps of each trial, in order: demonstrate, learn, reproduce, heldout (the
    # reproduction against demonstrations it did not learn from).
    steps: list[str] = dc.field(default_factory=lambda: ["demonstrate", "learn", "reproduce"])
    # Held-out demonstrations per trial (step heldout), seeded after the learnt ones.
    heldout: int = 0
    # Metrics in the table and the figure (flattened names, see ``trial.json``); every
    # metric is kept in each trial's ``trial.json``.
    metrics: list[str] = dc.field(default_factory=lambda: list(DEFAULT_METRICS))


# --------------------------------------------------------------------------------------
# Reading a sweep file


def _yaml_text(value):
    """A YAML value as one line of YAML (an override's value)."""
    if isinstance(value, str):
        return value
    text = yaml.safe_dump(value, default_flow_style=True, width=10**6)
    return text.strip().removesuffix("...").strip()


def _normalise(raw, source):
    """Axis values and case names as strings (what the typed schema holds)."""
    if not isinstance(raw, dict):
        raise ValueError(f"{source}: the top level must be a mapping of SweepSpec's fields")
    axes = raw.get("axes")
    if isinstance(axes, list):
        for i, axis in enumerate(axes):
            if not isinstance(axis, dict):
                raise ValueError(f"{source}: key 'axes[{i}]' must be a mapping of Axis's fields")
            if isinstance(axis.get("values"), list):
                axis["values"] = [_yaml_text(v) for v in axis["values"]]
            if isinstance(axis.get("cases"), dict):
                # YAML reads `off:` and `on:` as booleans; a case name is its text.
                axis["cases"] = {_case_name(k): v for k, v in axis["cases"].items()}
    return raw


def _case_name(key):
    if isinstance(key, bool):
        return "on" if key else "off"
    return str(key)


def parse_sweep(text, *, source="<sweep>"):
    """A :class:`SweepSpec` from YAML text, checked; ``source`` names it in errors.

    Raises ValueError in one line naming ``source`` and the key.
    """
    from pydrake.common.yaml import yaml_load_typed

    raw = parse_yaml(text, source)  # malformed YAML, a key given twice: one line
    if raw is None:
        raise ValueError(f"{source}: the sweep file is empty; give at least its 'scenario'")
    try:
        raw = _normalise(raw, source)
        check_types(raw, SweepSpec)
        spec = yaml_load_typed(
            schema=SweepSpec, data=yaml.safe_dump(raw, sort_keys=False), defaults=SweepSpec()
        )
        _check_spec(spec)
    except (RuntimeError, ValueError) as error:
        message = first_line(error)
        if message.startswith(f"{source}:"):
            raise ValueError(message) from None
        raise ValueError(f"{source}: {message}") from None
    return spec


def _check_spec(spec):
    if not spec.scenario:
        raise ValueError("key 'scenario' is required: a scenario file or cotter_pin, drawing")
    if spec.design not in DESIGNS:
        raise ValueError(f"key 'design' = {spec.design!r} is not one of {DESIGNS}")
    names = []
    for i, axis in enumerate(spec.axes):
        where = f"axes[{i}]"
        if bool(axis.values) == bool(axis.cases):
            raise ValueError(f"key '{where}' needs either 'values' or 'cases' (one of them)")
        if axis.cases and axis.keys:
            raise ValueError(f"key '{where}.keys' goes with 'values', not with 'cases'")
        if not axis.name:
            if not axis.keys:
                raise ValueError(f"key '{where}.name' is required (or 'keys' with 'values')")
            axis.name = axis.keys[0]
        if axis.values and not axis.keys:
            axis.keys = [axis.name]
        for name, overrides in axis.cases.items():
            for override in overrides:
                if "=" not in override:
                    raise ValueError(
                        f"key '{where}.cases.{name}': an override must read key=value, "
                        f"got {override!r}"
                    )
        names.append(axis.name)
    if len(set(names)) != len(names) or {"seed", "trial", "status"} & set(names):
        raise ValueError(
            f"key 'axes': names must be distinct and not seed, trial, status; got {names}"
        )
    if not spec.seeds or len(set(spec.seeds)) != len(spec.seeds) or min(spec.seeds) < 0:
        raise ValueError(f"key 'seeds' must list distinct non-negative integers, got {spec.seeds}")
    unknown = [s for s in spec.steps if s not in STEPS]
    if unknown or not spec.steps:
        raise ValueError(f"key 'steps' must be among {STEPS}, got {spec.steps}")
    expected = list(STEPS[: len(spec.steps)])
    if spec.steps != expected:
        raise ValueError(
            f"key 'steps' must be the first steps of {STEPS} in order, got {spec.steps}"
        )
    if "heldout" in spec.steps and spec.heldout < 1:
        raise ValueError(f"key 'heldout' must be at least 1 with step heldout, got {spec.heldout}")
    if spec.heldout < 0:
        raise ValueError(f"key 'heldout' must not be negative, got {spec.heldout}")
    for override in spec.set:
        if "=" not in override:
            raise ValueError(f"key 'set': an override must read key=value, got {override!r}")


def sweep_path(path):
    """A sweep file's path: ``path``, or the shipped sweep of that name (``example_delay``)."""
    path = Path(path)
    shipped = SWEEPS / f"{path}.yaml"
    if not path.exists() and path.suffix == "" and shipped.is_file():
        return Path(str(shipped))
    return path


def load_sweep(path):
    """Read and check a sweep file: (SweepSpec, base scenario YAML text, its source name).

    The base scenario is read and checked with the sweep's ``set`` overrides, so a bad base
    fails before any trial starts.
    """
    from hemg_drake.scenario import TASKS, load_scenario, shipped_scenario

    path = sweep_path(path)
    text = read_yaml_text(path, kind="sweep")
    spec = parse_sweep(text, source=str(path))
    scenario_path = path.parent / spec.scenario
    if not scenario_path.is_file() and spec.scenario in TASKS:
        scenario_path = shipped_scenario(spec.scenario)
    if not scenario_path.is_file():
        raise ValueError(
            f"{path}: key 'scenario': no scenario file {scenario_path} (nor a shipped "
            f"scenario: {list(TASKS)})"
        )
    try:
        load_scenario(scenario_path, overrides=spec.set)
    except ValueError as error:
        raise ValueError(f"{path}: key 'set': {first_line(error)}") from None
    return spec, scenario_path.read_text(encoding="utf-8"), str(scenario_path)


# --------------------------------------------------------------------------------------
# Trials


@dc.dataclass
class Trial:
    """One run of a sweep: its labels (axis name -> value or case), seed and overrides."""

    id: str
    labels: dict
    seed: int
    overrides: list
    # Overrides of the reproduction only (axes with ``reproduce_only``).
    reproduce_overrides: list = dc.field(default_factory=list)


def axis_points(axis):
    """(label, overrides) of each value or case of an axis."""
    if axis.cases:
        return [(name, list(overrides)) for name, overrides in axis.cases.items()]
    return [(value, [f"{key}={value}" for key in axis.keys]) for value in axis.values]


def _slug(text):
    keep = "".join(c if c.isalnum() or c in "-_.=" else "-" for c in text)
    return keep.strip("-")[:60]


def trials(spec):
    """The trials of a sweep, seed-major (a seed's trials one after another)."""
    combos = []
    if spec.design == "grid":
        points = [axis_points(axis) for axis in spec.axes]
        for choice in itertools.product(*points):
            labels = {axis.name: label for axis, (label, _) in zip(spec.axes, choice, strict=True)}
            pairs = list(zip(spec.axes, choice, strict=True))
            overrides = [o for axis, (_, group) in pairs if not axis.reproduce_only for o in group]
            later = [o for axis, (_, group) in pairs if axis.reproduce_only for o in group]
            combos.append((labels, overrides, later))
    else:
        for axis in spec.axes:
            for label, overrides in axis_points(axis):
                later = overrides if axis.reproduce_only else []
                combos.append(({axis.name: label}, [] if later else overrides, later))
    if not combos:
        combos = [({}, [], [])]
    result, seen = [], set()
    for seed in spec.seeds:
        for labels, overrides, later in combos:
            full = [*spec.set, *overrides, f"seed={seed}"]
            # A trial without reproduce-only overrides keeps the digest it always had.
            text = "\n".join(full + ([">reproduce", *later] if later else []))
            digest = hashlib.sha1(text.encode()).hexdigest()[:8]
            if digest in seen:
                continue
            seen.add(digest)
            name = ",".join(f"{k}={v}" for k, v in labels.items())
            trial_id = _slug(f"{name},seed={seed}" if name else f"seed={seed}") + f"-{digest}"
            result.append(Trial(trial_id, labels, seed, full, list(later)))
    return result
