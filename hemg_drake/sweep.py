"""Sweeps: one scenario run many times over a grid of settings and seeds, on all cores or Ray.

A sweep file (YAML, the fields of :class:`SweepSpec`) names a base scenario, the axes to
vary, the seeds and the steps of each trial::

    scenario: cotter_pin                     # a shipped scenario, or a path (from this file)
    set: [num_demonstrations=2]              # overrides of every trial
    axes:
      - name: delay_ms                       # a column of the table, an x axis of the figure
        keys: [mapping.delay_steps, feedback.delay_steps]   # each value sets all of them
        values: [0, 50, 100]
      - name: feedback
        cases:                               # named cases, each a list of overrides
          none: [feedback.gain=0]
          force: []
    seeds: [0, 100]                          # scenario key `seed` of each trial
    steps: [demonstrate, learn, reproduce]
    metrics: [demonstration.tracking_error_m, reproduction.success]

A trial is one combination of the axes' values (``design: grid``: all combinations;
``one_at_a_time``: each axis alone, the others left at the base scenario) and one seed. It
runs in a worker process from plain data (the scenario's YAML text and the overrides: no
Drake object pickles) and writes ``OUT/trials/<id>/`` atomically (built in a temporary
folder, renamed when done): ``trial.json`` (its overrides, status, one-line error if it
failed, metrics) and ``run/``, the run folder of :mod:`hemg_drake.pipeline`. The sweep then
gathers ``OUT/results.csv`` (``results.parquet`` too if pyarrow is importable) and
``OUT/results.png`` (per metric, one line per case of the other axes against each varied
axis, the mean over seeds and its spread, +-1 standard deviation).

Demonstrations do not depend on the ``learning`` and ``reproduction`` sections, so trials
that differ only there share them: they are recorded once per seed in ``OUT/cache/``.
"""

import contextlib
import csv
import dataclasses as dc
import hashlib
import importlib.resources
import io
import itertools
import json
import math
import os
import shutil
import sys
import time
from pathlib import Path

import yaml

from hemg_drake.fileio import read_yaml_text, write_bytes_atomic, write_text_atomic
from hemg_drake.yaml_schema import check_types, first_line

STEPS = ("demonstrate", "learn", "reproduce", "heldout")
DESIGNS = ("grid", "one_at_a_time")
BACKENDS = ("local", "ray")
# One thread per worker: the trials are the parallelism; more threads per process would
# only contend for the same cores (numba's parallel loops, BLAS inside numpy).
THREAD_ENV = {
    "NUMBA_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}
TRIAL_FILE = "trial.json"
# The sweeps shipped with the package (hemg_drake/sweeps/<name>.yaml): the studies.
SWEEPS = importlib.resources.files("hemg_drake") / "sweeps"
# Ray's object store: trials return a few numbers, so the smallest store Ray accepts.
RAY_OBJECT_STORE_BYTES = 80 * 1024 * 1024
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

    try:
        raw = yaml.safe_load(text) if text.strip() else None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(error, "problem", error)
        raise ValueError(f"{source}: malformed YAML{where}: {problem}") from None
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


def _axis_points(axis):
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
        points = [_axis_points(axis) for axis in spec.axes]
        for choice in itertools.product(*points):
            labels = {axis.name: label for axis, (label, _) in zip(spec.axes, choice, strict=True)}
            overrides = [o for _, group in choice for o in group]
            combos.append((labels, overrides))
    else:
        for axis in spec.axes:
            for label, overrides in _axis_points(axis):
                combos.append(({axis.name: label}, overrides))
    if not combos:
        combos = [({}, [])]
    result, seen = [], set()
    for seed in spec.seeds:
        for labels, overrides in combos:
            full = [*spec.set, *overrides, f"seed={seed}"]
            digest = hashlib.sha1("\n".join(full).encode()).hexdigest()[:8]
            if digest in seen:
                continue
            seen.add(digest)
            name = ",".join(f"{k}={v}" for k, v in labels.items())
            trial_id = _slug(f"{name},seed={seed}" if name else f"seed={seed}") + f"-{digest}"
            result.append(Trial(trial_id, labels, seed, full))
    return result


def _quiet(_line):
    pass


def flatten(prefix, data):
    """Scalars of a nested dict as ``prefix.a.b`` -> value; a list of numbers as its mean."""
    flat = {}
    for name, value in data.items():
        key = f"{prefix}.{name}"
        if isinstance(value, dict):
            flat.update(flatten(key, value))
        elif isinstance(value, (bool, int, float, str)) or value is None:
            flat[key] = value
        elif isinstance(value, (list, tuple)):
            numbers = [v for v in value if isinstance(v, (int, float)) and not isinstance(v, bool)]
            if numbers and len(numbers) == len([v for v in value if v is not None]):
                flat[key] = float(sum(numbers) / len(numbers))
    return flat


def demonstration_metrics(scenario, demos):
    """What the demonstrations show of the teleoperation loop (the delay study's figures).

    - ``tracking_error_m``: RMS over time of |p_WE - map(p_MS)|, the slave against the
      master's position mapped into W *now* (a transport delay shows as lag), mean over
      demonstrations.
    - ``master_oscillation_mm``: RMS of the stylus position above 5 Hz (the operator's
      plan moves below 2 Hz), mm; ``master_energy_peak_mj``: the stylus' peak kinetic
      energy, mJ; ``master_hit_wall``: fraction of demonstrations whose stylus left its
      workspace box.
    - ``gain_lag_s``: the lag maximising the cross-correlation of the operator's muscle
      activation and the gain K (0 to 0.5 s).
    - cotter pin: ``pin_out``: fraction of demonstrations whose tool point rose 8 cm (the
      pin comes out after its 3 mm detent, the grasp stretches 1 cm at most); drawing:
      ``strokes`` (mean count) and ``three_strokes`` (fraction with exactly three).
    """
    import numpy as np
    from scipy.signal import butter, sosfiltfilt

    from hemg_drake.evaluation import strokes

    mapping = scenario.workspace_mapping()
    half_box = 0.5 * np.asarray(scenario.master.workspace_size)
    record = {k: [] for k in ("tracking_error_m", "master_oscillation_mm", "master_energy_peak_mj",
                              "master_hit_wall", "gain_lag_s")}  # fmt: skip
    task = {"pin_out": [], "strokes": [], "three_strokes": []}
    for demo in demos:
        error = np.linalg.norm(demo.p_WE - mapping.master_to_slave(demo.p_MS), axis=1)
        record["tracking_error_m"].append(float(np.sqrt(np.mean(error**2))))
        rate = 1.0 / float(np.mean(np.diff(demo.time)))
        if len(demo.time) > 15 and rate > 12.0:
            sos = butter(2, 5.0, btype="high", fs=rate, output="sos")
            fast = sosfiltfilt(sos, demo.p_MS, axis=0)
            oscillation = 1e3 * float(np.sqrt(np.mean(np.sum(fast**2, axis=1))))
        else:
            oscillation = float("nan")
        record["master_oscillation_mm"].append(oscillation)
        v_MS = np.gradient(demo.p_MS, demo.time, axis=0)
        energy = 0.5 * scenario.master.mass * np.sum(v_MS**2, axis=1)
        record["master_energy_peak_mj"].append(1e3 * float(energy.max()))
        record["master_hit_wall"].append(float(np.any(np.abs(demo.p_MS) > half_box)))
        lag = _lag(demo.emg_time, demo.muscle_activation, demo.time, demo.gain)
        record["gain_lag_s"].append(lag)
        if scenario.task == "cotter_pin":
            task["pin_out"].append(float(demo.p_WE[:, 2].max() - demo.p_WE[0, 2] >= 0.08))
        else:
            count = len(strokes(demo.time, demo.p_WE, demo.f_WE))
            task["strokes"].append(float(count))
            task["three_strokes"].append(float(count == 3))
    record.update({k: v for k, v in task.items() if v})
    return {name: float(np.mean(values)) for name, values in record.items()}


def _lag(time_a, a, time_b, b, max_lag=0.5):
    """Delay of ``b`` behind ``a`` (s) at the peak of their cross-correlation, on b's grid."""
    import numpy as np

    a = np.interp(time_b, time_a, a)
    a, b = a - a.mean(), b - b.mean()
    if a.std() == 0 or b.std() == 0:
        return float("nan")
    dt = float(np.mean(np.diff(time_b)))
    lags = np.arange(0, int(max_lag / dt) + 1)
    scores = [np.dot(a[: len(a) - n], b[n:]) / (len(a) - n) for n in lags]
    return float(lags[int(np.argmax(scores))] * dt)


@contextlib.contextmanager
def _locked(path):
    """An exclusive lock on ``path`` (a file), where the filesystem supports it."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock, at worst the work is done twice
        yield
        return
    with open(path, "a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX)
        except OSError:
            pass
        yield


def _cached_demonstrations(task, scenario, run):
    """Copy the trial's demonstrations (and held-out ones) into ``run``, recording them in
    the cache first if no other trial has."""
    from hemg_drake import pipeline
    from hemg_drake.scenario import parse_scenario

    base = parse_scenario(task["scenario_text"], source=task["scenario_source"],
                          overrides=task["base_overrides"])  # fmt: skip
    # The learning and reproduction settings do not change a demonstration: the cached
    # run holds the base scenario's, and learn/reproduce apply the trial's overrides.
    shared = dc.replace(scenario, learning=base.learning, reproduction=base.reproduction)
    key_text = shared.to_yaml() + f"\nheldout: {task['heldout']}\n"
    key = hashlib.sha1(key_text.encode()).hexdigest()[:16]
    cache = Path(task["cache"])
    cache.mkdir(parents=True, exist_ok=True)
    entry = cache / key
    with _locked(cache / f".{key}.lock"):
        if not (entry / "manifest.json").is_file():
            tmp = cache / f".tmp-{key}-{os.getpid()}"
            shutil.rmtree(tmp, ignore_errors=True)
            try:
                pipeline.demonstrate(shared, tmp, replays=False, progress=_quiet)
                if task["heldout"]:
                    _record_heldout(shared, task["heldout"], tmp / "heldout.npz")
            except BaseException:
                shutil.rmtree(tmp, ignore_errors=True)
                raise
            shutil.rmtree(entry, ignore_errors=True)
            os.rename(tmp, entry)
    shutil.copytree(entry, run)


def _record_heldout(scenario, count, path):
    from hemg_drake.diagrams.demonstration import record_demonstration
    from hemg_drake.learning.demos import save_dataset

    first = scenario.seed + scenario.num_demonstrations
    demos = [record_demonstration(scenario, first + i) for i in range(count)]
    save_dataset(path, demos, dict(scenario=scenario.to_yaml(), task=scenario.task,
                                   log_period=scenario.log_period))  # fmt: skip


def heldout_metrics(run):
    """The reproduction in ``run`` against the held-out demonstrations: position RMSE
    time-normalised and after DTW, against their mean (as Table II, on unseen data)."""
    import numpy as np

    from hemg_drake.diagrams.reproduction import ReproductionLog
    from hemg_drake.learning.demos import load_dataset, observations
    from hemg_drake.tasks import metrics

    demos, _ = load_dataset(run / "heldout.npz")
    with np.load(run / "reproduction.npz", allow_pickle=False) as archive:
        log = ReproductionLog(**{name: archive[name] for name in archive.files})
    data = observations(demos)
    reproduced = log.observations()
    plain = metrics.time_normalised_rmse(reproduced, data)
    aligned = metrics.aligned_rmse(reproduced, metrics.mean_demonstration(data))
    return {
        "position_rmse_m": plain["position_rmse"],
        "velocity_rmse_m_per_s": plain["velocity_rmse"],
        "spatial_position_rmse_m": aligned["position_rmse"],
        "spatial_velocity_rmse_m_per_s": aligned["velocity_rmse"],
    }


def _trial_metrics(task, run):
    from hemg_drake import pipeline
    from hemg_drake.scenario import parse_scenario

    overrides = task["overrides"]
    scenario = parse_scenario(task["scenario_text"], source=task["scenario_source"],
                              overrides=overrides, overrides_source="override")  # fmt: skip
    steps, result = task["steps"], {}
    if "demonstrate" in steps:
        _cached_demonstrations(task, scenario, run)
        demos, _ = pipeline.load_demonstrations(run / "dataset.npz")
        result.update(flatten("demonstration", demonstration_metrics(scenario, demos)))
    if "learn" in steps:
        model = pipeline.learn(run, overrides=overrides, progress=_quiet)
        result["learn.n_iter"] = int(model.n_iter_)
        result["learn.converged"] = bool(model.converged_)
    if "reproduce" in steps:
        reproduced = pipeline.reproduce(run, overrides=overrides, replay=False, progress=_quiet)
        reproduced = {k: v for k, v in reproduced.items() if k not in ("start", "start_offset")}
        result.update(flatten("reproduction", reproduced))
    if "heldout" in steps:
        result.update(flatten("heldout", heldout_metrics(run)))
    return result


def run_trial(task):
    """Run one trial (a dict of plain data, see :func:`_task`) in this process.

    Builds ``task["dir"]`` in a temporary folder beside it and renames it when done, so
    a trial folder exists only complete. Any error is caught and recorded in one line.

    Returns
    -------
    dict, the record written to ``trial.json``: id, labels, seed, overrides, status
    ("done" or "failed"), error, elapsed_s, metrics.
    """
    began = time.perf_counter()
    final = Path(task["dir"])
    tmp = final.parent / f".tmp-{final.name}-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    record = dict(id=task["id"], labels=task["labels"], seed=task["seed"],
                  overrides=task["overrides"], status="done", error="", metrics={})  # fmt: skip
    try:
        record["metrics"] = _trial_metrics(task, tmp / "run")
    except Exception as error:  # noqa: BLE001 - a failed trial is a result, not a crash
        record.update(status="failed", error=f"{type(error).__name__}: {first_line(error)}")
    record["elapsed_s"] = time.perf_counter() - began
    write_text_atomic(tmp / TRIAL_FILE, json.dumps(record, indent=2, default=_json_default) + "\n")
    if final.exists():
        shutil.rmtree(final)
    os.rename(tmp, final)
    return json.loads((final / TRIAL_FILE).read_text(encoding="utf-8"))


def _json_default(value):
    try:
        return float(value)
    except (TypeError, ValueError):
        return str(value)


# --------------------------------------------------------------------------------------
# Running a sweep


class Progress:
    """A one-line progress bar on a stream: done, running, failed, time left."""

    def __init__(self, total, workers, stream=None, width=24):
        self.total, self.workers, self.width = total, workers, width
        self.stream = sys.stderr if stream is None else stream
        self.done = self.failed = self.skipped = 0
        self.began = time.perf_counter()
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def line(self):
        finished = self.done + self.failed
        remaining = self.total - finished
        running = min(self.workers, remaining)
        ran = finished - self.skipped
        elapsed = time.perf_counter() - self.began
        if ran > 0 and remaining > 0:
            left = f"{_duration(elapsed / ran * remaining)} left"
        elif remaining == 0:
            left = f"took {_duration(elapsed)}"
        else:
            left = "time left unknown"
        filled = round(self.width * finished / max(self.total, 1))
        bar = "#" * filled + "-" * (self.width - filled)
        return (f"[{bar}] {finished}/{self.total} done ({self.failed} failed), "
                f"{running} running, {left}")  # fmt: skip

    def update(self, status=None, *, skipped=False):
        if status == "done":
            self.done += 1
        elif status == "failed":
            self.failed += 1
        if skipped:
            self.skipped += 1
        end = "\r" if self.tty and self.done + self.failed < self.total else "\n"
        try:
            print(self.line(), end=end, file=self.stream, flush=True)
        except (BrokenPipeError, ValueError):
            pass


def _duration(seconds):
    seconds = int(round(seconds))
    return f"{seconds // 60}:{seconds % 60:02d}" if seconds >= 60 else f"{seconds} s"


def _task(trial, spec, text, source, out):
    return dict(
        id=trial.id, labels=trial.labels, seed=trial.seed, overrides=trial.overrides,
        base_overrides=[*spec.set, f"seed={trial.seed}"], steps=list(spec.steps),
        heldout=spec.heldout, scenario_text=text, scenario_source=source,
        dir=str(out / "trials" / trial.id), cache=str(out / "cache"),
    )  # fmt: skip


def finished_record(out, trial):
    """The trial's record if it finished (status done) in ``out``, else None."""
    path = Path(out) / "trials" / trial.id / TRIAL_FILE
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    return record if record.get("status") == "done" else None


@contextlib.contextmanager
def _thread_env():
    """THREAD_ENV in os.environ while workers start (they inherit it), restored after."""
    saved = {name: os.environ.get(name) for name in THREAD_ENV}
    os.environ.update(THREAD_ENV)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _run_local(tasks, workers, on_record):
    import concurrent.futures as cf
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    with _thread_env(), cf.ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = {pool.submit(run_trial, task): task for task in tasks}
        try:
            for future in cf.as_completed(futures):
                try:
                    record = future.result()
                except Exception as error:  # noqa: BLE001 - a worker died
                    record = _crashed(futures[future], error)
                on_record(record)
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def _crashed(task, error):
    return dict(id=task["id"], labels=task["labels"], seed=task["seed"],
                overrides=task["overrides"], status="failed", metrics={}, elapsed_s=0.0,
                error=f"worker died: {type(error).__name__}: {first_line(error)}")  # fmt: skip



def only_loopback():
    """True if this process's network interfaces are just ``lo`` (a loopback-only network
    namespace); ``socket.if_nameindex`` asks the kernel for this process's namespace."""
    import socket

    try:
        return [name for _, name in socket.if_nameindex()] == ["lo"]
    except OSError:
        return False

def _run_ray(tasks, workers, address, on_record):
    try:
        import ray
    except ImportError:
        raise ValueError(
            "--backend ray needs Ray: pip install 'hemg-drake[ray]' (or pip install ray)"
        ) from None
    runtime_env = {"env_vars": dict(THREAD_ENV)}
    if address:
        ray.init(address=address, runtime_env=runtime_env, log_to_driver=False)
    else:
        # Ray binds the machine's own address whatever _node_ip_address says (measured with
        # Ray 2.60): start a local instance only where the loopback is the only network.
        if not only_loopback():
            raise ValueError(
                "--backend ray without --address starts a local Ray, which binds this "
                "machine's network address; run it in a loopback-only network namespace "
                "(as root: unshare -n, then ip link set lo up), or join a cluster with "
                "--address, or use the local backend (the default)"
            )
        # A private local instance, without the dashboard.
        ray.init(
            _node_ip_address="127.0.0.1", include_dashboard=False, num_cpus=workers,
            object_store_memory=RAY_OBJECT_STORE_BYTES, runtime_env=runtime_env,
            log_to_driver=False,
        )  # fmt: skip
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(run_trial)
        pending = {remote.remote(task): task for task in tasks}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                task = pending.pop(ref)
                try:
                    record = ray.get(ref)
                except Exception as error:  # noqa: BLE001 - the task's worker died
                    record = _crashed(task, error)
                on_record(record)
    finally:
        ray.shutdown()


def run_sweep(path, out, *, backend="local", workers=None, address=None, resume=False,
              stream=None):  # fmt: skip
    """Run a sweep file's trials into ``out``; write the table and the figure.

    Parameters
    ----------
    path : path-like, the sweep file.
    out : path-like, the sweep's folder (created).
    backend : {"local", "ray"}
        "local": a process pool on this machine; "ray": one Ray task per trial
        (``address`` joins a cluster; none starts a local instance on 127.0.0.1).
    workers : int, optional
        Processes (local) or CPUs of the local Ray instance; default all cores.
    resume : bool
        Skip the trials already done in ``out`` (failed ones run again). Without it, a
        folder that holds trials is refused.
    stream : file, the progress bar's (default stderr).

    Returns
    -------
    list of dict, the trials' records, in the sweep's order.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    spec, text, source = load_sweep(path)
    spec_text = sweep_path(path).read_text(encoding="utf-8")
    out = Path(out)
    trials_dir = out / "trials"
    if not resume and trials_dir.is_dir() and any(trials_dir.iterdir()):
        raise ValueError(
            f"{out}: holds a sweep's trials already: pass --resume to continue it, or "
            f"choose another --out"
        )
    trials_dir.mkdir(parents=True, exist_ok=True)
    for stale in itertools.chain(trials_dir.glob(".tmp-*"), (out / "cache").glob(".tmp-*")):
        shutil.rmtree(stale, ignore_errors=True)
    write_text_atomic(out / "sweep.yaml", spec_text)
    all_trials = trials(spec)
    records = {}
    for trial in all_trials:
        record = finished_record(out, trial) if resume else None
        if record is not None:
            records[trial.id] = record
    todo = [t for t in all_trials if t.id not in records]
    progress = Progress(len(all_trials), min(workers, max(len(todo), 1)), stream)
    # Trials done in an earlier run count as done, not in the time left.
    progress.done = progress.skipped = len(records)
    progress.update()

    def on_record(record):
        records[record["id"]] = record
        progress.update(record["status"])

    tasks = [_task(t, spec, text, source, out) for t in todo]
    if tasks:
        if backend == "local":
            _run_local(tasks, workers, on_record)
        else:
            _run_ray(tasks, workers, address, on_record)
    ordered = [records[t.id] for t in all_trials]
    write_results(ordered, spec, out)
    return ordered


# --------------------------------------------------------------------------------------
# The table and the figure


def table_rows(records, spec):
    """One row per trial: trial, status, seed, the axes' labels, elapsed_s, error, metrics."""
    rows = []
    for record in records:
        row = {"trial": record["id"], "status": record["status"], "seed": record["seed"]}
        for axis in spec.axes:
            row[axis.name] = record["labels"].get(axis.name, "")
        row["elapsed_s"] = round(float(record.get("elapsed_s", 0.0)), 3)
        row["error"] = record.get("error", "")
        for name in spec.metrics:
            row[name] = record["metrics"].get(name, "")
        rows.append(row)
    return rows


def write_results(records, spec, out):
    """``results.csv`` (and ``results.parquet`` with pyarrow) and ``results.png``."""
    out = Path(out)
    rows = table_rows(records, spec)
    columns = list(rows[0]) if rows else ["trial", "status"]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(out / "results.csv", buffer.getvalue())
    written = [out / "results.csv"]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        pass
    else:
        table = pa.Table.from_pylist([{k: _cell(v) for k, v in row.items()} for row in rows])
        sink = io.BytesIO()
        pq.write_table(table, sink)
        write_bytes_atomic(out / "results.parquet", sink.getvalue())
        written.append(out / "results.parquet")
    if spec.axes and spec.metrics and any(r["status"] == "done" for r in records):
        written.append(plot_results(records, spec, out / "results.png"))
    return written


def _cell(value):
    return "" if value is None else str(value) if isinstance(value, (list, dict)) else value


def _number(value):
    if isinstance(value, bool):
        return float(value)
    if isinstance(value, (int, float)):
        return float(value)
    return math.nan


def _as_float(label):
    try:
        return float(yaml.safe_load(str(label)))
    except (TypeError, ValueError, yaml.YAMLError):
        return None


def plot_results(records, spec, path, *, title=None):
    """Per metric (rows) and varied axis (columns): the metric's mean over seeds against the
    axis' values, one line per case of the other axes (grid) and +-1 standard deviation
    shaded. Booleans are shown as rates (the mean of 0/1)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from hemg_drake.viz.figures import save_figure

    done = [r for r in records if r["status"] == "done"]
    metrics_ = list(spec.metrics)
    axes_ = list(spec.axes)
    figure, grid = plt.subplots(len(metrics_), len(axes_), squeeze=False,
                                figsize=(4.2 * len(axes_), 2.6 * len(metrics_)))  # fmt: skip
    for column, axis in enumerate(axes_):
        labels = [label for label, _ in _axis_points(axis)]
        numeric = [_as_float(label) for label in labels]
        numeric_x = all(v is not None for v in numeric)
        x = np.array(numeric if numeric_x else range(len(labels)), dtype=float)
        others = [a for a in axes_ if a is not axis] if spec.design == "grid" else []
        present = {tuple(r["labels"].get(a.name, "") for a in others) for r in done}
        # The other axes' cases in the sweep file's order.
        ordered = itertools.product(*[[label for label, _ in _axis_points(a)] for a in others])
        groups = [group for group in ordered if group in present]
        others = [a.name for a in others]
        for row, metric in enumerate(metrics_):
            ax = grid[row][column]
            for group in groups:
                mean, spread = [], []
                for label in labels:
                    values = [
                        _number(r["metrics"].get(metric)) for r in done
                        if r["labels"].get(axis.name) == label
                        and tuple(r["labels"].get(n, "") for n in others) == group
                    ]  # fmt: skip
                    values = [v for v in values if math.isfinite(v)]
                    mean.append(np.mean(values) if values else np.nan)
                    spread.append(np.std(values) if values else np.nan)
                mean, spread = np.array(mean), np.array(spread)
                name = ", ".join(f"{n}={g}" for n, g in zip(others, group, strict=True))
                (line,) = ax.plot(x, mean, "o-", label=name or None, markersize=3)
                ax.fill_between(x, mean - spread, mean + spread, alpha=0.2, color=line.get_color())
            if not numeric_x:
                ax.set_xticks(x, labels)
            if row == len(metrics_) - 1:
                ax.set_xlabel(axis.name)
            if column == 0:
                ax.set_ylabel(metric.replace(".", ".\n", 1), fontsize=8)
            ax.grid(alpha=0.3)
            if row == 0 and groups and groups[0]:
                ax.legend(fontsize=7)
    seeds = len(spec.seeds)
    figure.suptitle(title or f"{len(done)} trials, mean and +-1 std over {seeds} seed(s)",
                    fontsize=10)  # fmt: skip
    figure.tight_layout(rect=(0, 0, 1, 1 - 0.25 / figure.get_figheight()))
    save_figure(figure, path)
    plt.close(figure)
    return path


def summary(records, spec):
    """Lines of text: the mean over seeds of each metric per setting."""
    import numpy as np

    lines, groups = [], {}
    for record in records:
        key = tuple(record["labels"].get(a.name, "") for a in spec.axes)
        groups.setdefault(key, []).append(record)
    header = [a.name for a in spec.axes] + ["done"] + list(spec.metrics)
    lines.append("  ".join(header))
    for key, group in groups.items():
        done = [r for r in group if r["status"] == "done"]
        cells = [str(k) if k != "" else "-" for k in key] + [f"{len(done)}/{len(group)}"]
        for metric in spec.metrics:
            values = [_number(r["metrics"].get(metric)) for r in done]
            values = [v for v in values if math.isfinite(v)]
            cells.append(f"{np.mean(values):.4g}" if values else "-")
        lines.append("  ".join(cells))
    return lines
