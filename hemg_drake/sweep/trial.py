"""One trial of a sweep, run in a worker from plain data: its steps, its metrics and its
``trial.json``; demonstrations shared between trials through the sweep's cache."""

import contextlib
import dataclasses as dc
import errno
import hashlib
import json
import os
import re
import shutil
import time
from pathlib import Path

from hemg_drake.fileio import write_text_atomic
from hemg_drake.yaml_schema import first_line

TRIAL_FILE = "trial.json"


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
    - ``contact_force_peak_n``: the largest |f_WE| (N); ``muscle_effort``: the operator's
      muscle activation averaged over time (dimensionless; the shared-control study).
    - cotter pin: ``pin_out``: fraction of demonstrations whose tool point rose 8 cm (the
      pin comes out after its 3 mm detent, the grasp stretches 1 cm at most);
      ``completion_s``: when it had (mean over those that did; NaN if none); drawing:
      ``strokes`` (mean count), ``three_strokes`` (fraction with exactly three) and
      ``completion_s``: when the third stroke's ink ended (mean over the demonstrations
      with three; NaN if none).
    """
    import numpy as np
    from scipy.signal import butter, sosfiltfilt

    from hemg_drake.evaluation import stroke_runs

    mapping = scenario.workspace_mapping()
    half_box = 0.5 * np.asarray(scenario.master.workspace_size)
    record = {k: [] for k in ("tracking_error_m", "master_oscillation_mm", "master_energy_peak_mj",
                              "master_hit_wall", "gain_lag_s", "contact_force_peak_n",
                              "muscle_effort")}  # fmt: skip
    task = {"pin_out": [], "completion_s": [], "strokes": [], "three_strokes": []}
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
        record["contact_force_peak_n"].append(float(np.linalg.norm(demo.f_WE, axis=1).max()))
        record["muscle_effort"].append(float(np.mean(demo.muscle_activation)))
        if scenario.task == "cotter_pin":
            risen = np.flatnonzero(demo.p_WE[:, 2] - demo.p_WE[0, 2] >= 0.08)
            task["pin_out"].append(float(len(risen) > 0))
            if len(risen):
                task["completion_s"].append(float(demo.time[risen[0]]))
        else:
            runs = stroke_runs(demo.time, demo.f_WE)[0]
            task["strokes"].append(float(len(runs)))
            task["three_strokes"].append(float(len(runs) == 3))
            if len(runs) == 3:
                task["completion_s"].append(float(demo.time[runs[-1][1] - 1]))
    if not task["completion_s"]:
        task["completion_s"] = [float("nan")]
    record.update({k: v for k, v in task.items() if v})
    return {name: float(np.mean(values)) for name, values in record.items()}


def study_metrics(scenario, demos, path):
    """The shared-control study's measures (:func:`~hemg_drake.analysis.effort.
    interaction_metrics`), mean over the demonstrations, from the interaction log at
    ``path`` (none if the run has no such file): ``hand_impulse_n_s``, ``hand_work_j``,
    ``passivity_energy_min_j`` (the least over them), and as logged ``gave_up``, ``held_s``,
    ``disagreement_m``, ``phase_lag_s``, ``phase_missed``."""
    import numpy as np

    from hemg_drake.analysis.effort import interaction_metrics
    from hemg_drake.fileio import load_npz

    if not Path(path).is_file():
        return {}
    arrays = load_npz(path, kind="interaction log")
    model = None
    if any(name.endswith(".assist.phase") for name in arrays):
        from hemg_drake.diagrams.assist import assist_model

        model = assist_model(scenario)
    records = []
    for c, demo in enumerate(demos):
        prefix = f"demo{c}."
        signals = {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}
        records.append(interaction_metrics(signals, demo, model))
    result = {}
    for name in records[0]:
        values = np.array([record.get(name, np.nan) for record in records], dtype=float)
        least = name == "passivity_energy_min_j"
        result[name] = float(np.nanmin(values) if least else np.nanmean(values)) \
            if np.isfinite(values).any() else float("nan")
    return result


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
    from hemg_drake.diagrams.demonstration import build_demonstration_diagram, run_demonstration
    from hemg_drake.learning.demos import save_dataset

    first = scenario.seed + scenario.num_demonstrations
    built = build_demonstration_diagram(scenario)  # once: the seeds live in the Context
    demos = [run_demonstration(built, first + i) for i in range(count)]
    save_dataset(path, demos, dict(scenario=scenario.to_yaml(), task=scenario.task,
                                   log_period=scenario.log_period))  # fmt: skip


def heldout_metrics(run):
    """The reproduction in ``run`` against the held-out demonstrations: position RMSE
    time-normalised and after DTW, against their mean (as Table II, on unseen data;
    :func:`hemg_drake.evaluation.table_ii_against`)."""
    import numpy as np

    from hemg_drake.diagrams.reproduction import ReproductionLog
    from hemg_drake.evaluation import table_ii_against
    from hemg_drake.learning.demos import load_dataset

    demos, _ = load_dataset(run / "heldout.npz")
    with np.load(run / "reproduction.npz", allow_pickle=False) as archive:
        log = ReproductionLog(**{name: archive[name] for name in archive.files})
    return table_ii_against(demos, log)


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
        measured = demonstration_metrics(scenario, demos)
        measured.update(study_metrics(scenario, demos, run / pipeline.INTERACTION_FILE))
        result.update(flatten("demonstration", measured))
    if "learn" in steps:
        model = pipeline.learn(run, overrides=overrides, progress=_quiet)
        result["learn.n_iter"] = int(model.n_iter_)
        result["learn.converged"] = bool(model.converged_)
    if "reproduce" in steps:
        later = [*overrides, *task.get("reproduce_overrides", [])]
        reproduced = pipeline.reproduce(run, overrides=later, replay=False, progress=_quiet)
        reproduced = {k: v for k, v in reproduced.items() if k not in ("start", "start_offset")}
        result.update(flatten("reproduction", reproduced))
    if "heldout" in steps:
        result.update(flatten("heldout", heldout_metrics(run)))
    return result


# Errors of the disk itself: the sweep stops (every later trial would fail the same way)
# rather than recording them as the trial's result.
DISK_ERRORS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EIO)


def _shown(filename):
    """A path with each temporary folder of a trial, a cache entry or a run folder's new
    version (``.tmp-<id>-<pid>``, ``.<name>.hemg-drake-new-<pid>``) shown by its final name."""
    from hemg_drake.run_folder import NEW

    parts = []
    for part in Path(filename).parts:
        part = re.sub(rf"^\.(.+)\.{NEW}-\d+$", r"\1", part)
        parts.append(re.sub(r"^\.tmp-(.+)-\d+$", r"\1", part))
    return str(Path(*parts))


def run_trial(task):
    """Run one trial (a dict of plain data, see :func:`_task`) in this process.

    Builds ``task["dir"]`` in a temporary folder beside it (``.tmp-<id>-<pid>``) and
    swaps it in when done, so a trial folder exists only complete: interrupted or killed,
    a trial leaves at most its temporary folder, which the sweep removes. Any error of the
    trial is recorded in one line; an error of the disk (full, read-only, I/O) is raised
    as an OSError naming the file, its temporary folder removed.

    Returns
    -------
    dict, the record written to ``trial.json``: id, labels, seed, overrides, status
    ("done" or "failed"), error, elapsed_s, metrics.
    """
    began = time.perf_counter()
    final = Path(task["dir"])
    tmp = final.parent / f".tmp-{final.name}-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        tmp.mkdir(parents=True)
        record = dict(id=task["id"], labels=task["labels"], seed=task["seed"],
                      overrides=task["overrides"], status="done", error="", metrics={})  # fmt: skip
        if task.get("reproduce_overrides"):
            record["reproduce_overrides"] = task["reproduce_overrides"]
        try:
            record["metrics"] = _trial_metrics(task, tmp / "run")
        except OSError as error:
            if error.errno in DISK_ERRORS:
                raise
            record.update(status="failed", error=f"{type(error).__name__}: {first_line(error)}")
        except Exception as error:  # noqa: BLE001 - a failed trial is a result, not a crash
            record.update(status="failed", error=f"{type(error).__name__}: {first_line(error)}")
        record["elapsed_s"] = time.perf_counter() - began
        text = json.dumps(record, indent=2, default=_json_default) + "\n"
        write_text_atomic(tmp / TRIAL_FILE, text)
        if final.exists():  # a failed trial run again: swap, then drop the old one
            from hemg_drake.folder_versions import exchange

            exchange(tmp, final)
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            os.rename(tmp, final)
    except OSError as error:
        shutil.rmtree(tmp, ignore_errors=True)
        if error.errno in DISK_ERRORS:
            where = _shown(error.filename or final)
            # The reason alone: a stage's "nothing in <its temporary folder> was changed"
            # names a folder the person never sees.
            reason = (error.strerror or os.strerror(error.errno)).split("; nothing in ")[0]
            raise OSError(error.errno, reason, where) from None
        raise
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return json.loads(text)


def _json_default(value):
    try:
        return float(value)
    except (TypeError, ValueError):
        return str(value)
