"""Demonstrations as a LeRobot dataset, format v3.0 (LeRobot >= 0.4.0), written with pyarrow.

LeRobot (huggingface/lerobot, "LeRobotDataset v3.0"; ``codebase_version`` "v3.0", read by
lerobot 0.4.0 - 0.6) keeps a dataset in one folder::

    meta/info.json                 fps, features (dtype, shape, names), counts, path templates
    meta/stats.json                per feature: min, max, mean, std, count, q01 .. q99
    meta/tasks.parquet             task text (the pandas index, column ``task``) -> task_index
    meta/episodes/chunk-000/file-000.parquet   one row per episode: length, tasks, where its
                                   frames are (data/chunk_index, data/file_index,
                                   dataset_from_index, dataset_to_index), stats/<feature>/<stat>
    data/chunk-<c>/file-<f>.parquet           the frames, many episodes per file; a new file
                                   when one would pass ``data_files_size_in_mb``, a new chunk
                                   every ``chunks_size`` files; an episode is never split

There are no ``videos/``: the simulated cell has no cameras, so no feature has dtype
"video" or "image" and ``video_path`` is null. A demonstration maps onto the frames at its
log period (fps = 1 / log_period, 100 at Table I's 0.01 s), in float32 as LeRobot's
policies expect (SI units, world frame W):

- ``observation.state`` (17): the arm's joint positions ``q`` (7, rad, right_s0 ...
  right_w2), the tool's pose: the point E ``p_WE`` (3, m) and the frame's orientation as a
  unit quaternion ``quat_WE`` in Drake's order [w, x, y, z] (4, signs continuous over the
  dataset, :func:`~hemg_drake.learning.demos.tool_quaternions`), and the point's velocity
  ``v_WE`` (3, m/s); each entry named in the feature's ``names``. A dataset recorded before
  the joints were logged gives ``[p_WE, v_WE]`` (6), with a warning;
- ``observation.force`` (3): force of the environment on the tool point, f_WE (N);
- ``action`` (4): what the operator commanded, ``[p_WE_desired, K]``: the CLIK's reference
  (m) and the stiffness of eq. 22 (as logged), as in the robomimic export;
- ``operator.emg_envelope``, ``operator.activation`` (1): the raw RMS envelope of the summed
  sEMG (MYO units, eqs. 1-2) and the muscle activation a(u); ``operator.p_MS`` (3): the
  master's stylus tip (m, M). The operator's side, named outside ``observation.`` so that
  LeRobot's policies do not take it as robot state;
- ``hsmm.state`` (int64): with a model learnt from this dataset, each frame's HSMM state
  (segmental Viterbi, :meth:`HSMM.decode`);
- ``timestamp`` = frame_index / fps exactly (float32 of the double quotient), ``frame_index``,
  ``episode_index``, ``index`` (over the dataset), ``task_index``.

:func:`export_lerobot` builds the whole dataset in a temporary sibling folder and renames it
into place last: a failure (a full disk included) leaves the previous state exactly. An
existing folder is replaced only if it is empty or a previous export by this tool
(``meta/hemg_drake.json`` lists every file it wrote, and nothing else is there).
"""

import contextlib
import ctypes
import errno
import json
import os
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np

import hemg_drake
from hemg_drake.learning.demos import Demonstration, tool_quaternions
from hemg_drake.learning.export import NO_ARM_NOTE, write_error
from hemg_drake.robots.baxter import JOINT_NAMES

CODEBASE_VERSION = "v3.0"
# The LeRobot release whose reader the optional test loads the dataset with.
LEROBOT_VERSION = "0.4.4"
CHUNKS_SIZE = 1000
DATA_FILES_SIZE_IN_MB = 100
VIDEO_FILES_SIZE_IN_MB = 200
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
TASKS_PATH = "meta/tasks.parquet"
MARKER = "meta/hemg_drake.json"
WRITER = "hemg-drake export --format lerobot"
TASK_TEXT = {
    "cotter_pin": "pull the cotter pin out of its hole",
    "drawing": "draw the strokes on the sheet with the pen",
}
_INSTALL_HINT = "install the optional extra: pip install 'hemg-drake[lerobot]'"

# name -> (shape, names, unit, description, the demonstration's columns)
_FLOAT_FEATURES = {
    "observation.state": (
        ["p_WE_x", "p_WE_y", "p_WE_z", "v_WE_x", "v_WE_y", "v_WE_z"], "m, m/s",
        "tool point E in the world: position and velocity", ("p_WE", "v_WE"),
    ),
    "observation.force": (
        ["f_WE_x", "f_WE_y", "f_WE_z"], "N",
        "force of the environment on the tool point, in the world (no torque is logged)",
        ("f_WE",),
    ),
    "action": (
        ["p_WE_desired_x", "p_WE_desired_y", "p_WE_desired_z", "K"], "m, as logged",
        "the operator's command: the CLIK's reference for the tool point and the stiffness "
        "K of eq. 22", ("p_WE_desired", "gain"),
    ),
    "operator.emg_envelope": (
        ["envelope"], "MYO units", "raw RMS envelope of the summed sEMG (eqs. 1-2)",
        ("envelope",),
    ),
    "operator.activation": (
        ["a"], "1", "the operator's muscle activation a(u) in [0, 1] (eq. 22)", ("activation",),
    ),
    "operator.p_MS": (
        ["p_MS_x", "p_MS_y", "p_MS_z"], "m", "the master's stylus tip S in the master frame M",
        ("p_MS",),
    ),
}
# observation.state of a dataset that logged the arm's joints (quat_WE: tool_quaternions).
_ARM_STATE = (
    [*JOINT_NAMES, "p_WE_x", "p_WE_y", "p_WE_z", "quat_WE_w", "quat_WE_x", "quat_WE_y",
     "quat_WE_z", "v_WE_x", "v_WE_y", "v_WE_z"], "rad, m, 1, m/s",
    "the arm's joint positions q, the tool's pose in the world (point E, the frame's "
    "orientation as a unit quaternion w, x, y, z) and the point's velocity",
    ("q", "p_WE", "quat_WE", "v_WE"),
)  # fmt: skip
HSMM_STATE = "hsmm.state"
_INDEX_FEATURES = ("frame_index", "episode_index", "index", "task_index")


def _pyarrow():
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError as error:
        raise ModuleNotFoundError(
            f"LeRobot export needs pyarrow ({_INSTALL_HINT})", name="pyarrow"
        ) from error
    return pyarrow, pyarrow.parquet


def _float_features(arm):
    return {**_FLOAT_FEATURES, "observation.state": _ARM_STATE} if arm else _FLOAT_FEATURES


def features(hsmm_state=False, arm=True):
    """The dataset's features, as ``meta/info.json`` lists them (no video: no cameras);
    ``arm`` False: a dataset without the arm's joints (observation.state [p_WE, v_WE])."""
    result = {}
    for name, (names, unit, description, _) in _float_features(arm).items():
        result[name] = {
            "dtype": "float32", "shape": [len(names)], "names": names,
            "info": {"unit": unit, "description": description},
        }  # fmt: skip
    if hsmm_state:
        result[HSMM_STATE] = {
            "dtype": "int64", "shape": [1], "names": None,
            "info": {"unit": "1", "description": "HSMM state (segmental Viterbi) of the "
                     "model learnt from this dataset"},
        }  # fmt: skip
    result["timestamp"] = {"dtype": "float32", "shape": [1], "names": None}
    for name in _INDEX_FEATURES:
        result[name] = {"dtype": "int64", "shape": [1], "names": None}
    return result


def check_fps(demos, fps):
    """fps as a whole number, with every demonstration sampled at k / fps (within 1 us)."""
    if fps is None:
        steps = np.concatenate([np.diff(demo.time) for demo in demos if len(demo) > 1] or [[]])
        if not len(steps):
            raise ValueError("LeRobot export: give fps; no demonstration has two samples")
        fps = 1.0 / float(np.median(steps))
    rounded = int(round(fps))
    if rounded < 1 or abs(rounded - fps) > 1e-6 * rounded:
        raise ValueError(f"LeRobot export: fps must be a whole number of frames per second, got {fps}")
    for c, demo in enumerate(demos):
        error = np.abs(demo.time - demo.time[0] - np.arange(len(demo)) / rounded)
        if error.max(initial=0.0) > 1e-6:
            raise ValueError(
                f"LeRobot export: demonstration {c + 1} is not sampled every 1/{rounded} s "
                f"(off by up to {error.max():.3g} s)"
            )
    return rounded


def feature_stats(values):
    """LeRobot's statistics of one feature, values of shape (n, d): arrays of shape (d,)."""
    values = np.asarray(values, dtype=np.float64)
    stats = {
        "min": values.min(axis=0), "max": values.max(axis=0), "mean": values.mean(axis=0),
        "std": values.std(axis=0), "count": np.array([len(values)]),
    }  # fmt: skip
    for q in QUANTILES:
        stats[f"q{int(round(q * 100)):02d}"] = np.quantile(values, q, axis=0)
    return stats


def _episode_columns(demo, c, first_index, fps, states, quats):
    n = len(demo)
    columns = {}
    for name, (_, _, _, fields) in _float_features(quats is not None).items():
        parts = [np.reshape(quats if field == "quat_WE" else getattr(demo, field), (n, -1))
                 for field in fields]  # fmt: skip
        columns[name] = np.hstack(parts).astype(np.float32)
    if states is not None:
        columns[HSMM_STATE] = np.asarray(states, dtype=np.int64).reshape(n, 1)
    frame_index = np.arange(n, dtype=np.int64)
    columns["timestamp"] = (frame_index / fps).astype(np.float32).reshape(n, 1)
    columns["frame_index"] = frame_index.reshape(n, 1)
    columns["episode_index"] = np.full((n, 1), c, dtype=np.int64)
    columns["index"] = (first_index + frame_index).reshape(n, 1)
    columns["task_index"] = np.zeros((n, 1), dtype=np.int64)
    return columns


def _table(pa, columns, feature_spec):
    arrays, names = [], []
    for name, values in columns.items():
        type_ = pa.float32() if feature_spec[name]["dtype"] == "float32" else pa.int64()
        if feature_spec[name]["shape"] == [1]:
            arrays.append(pa.array(values[:, 0], type=type_))
        else:
            flat = pa.array(values.reshape(-1), type=type_)
            arrays.append(pa.FixedSizeListArray.from_arrays(flat, values.shape[1]))
        names.append(name)
    return pa.Table.from_arrays(arrays, names=names)


def _stats_json(stats):
    return {
        name: {key: value.tolist() for key, value in feature.items()}
        for name, feature in stats.items()
    }


def _check_inputs(demos, states):
    demos = list(demos)
    if not demos or not all(isinstance(d, Demonstration) for d in demos):
        raise ValueError("export_lerobot needs a non-empty list of Demonstration")
    if any(len(demo) < 1 for demo in demos):
        raise ValueError("export_lerobot: every demonstration needs at least one sample")
    if states is not None:
        states = [np.asarray(s) for s in states]
        if len(states) != len(demos) or any(
            s.shape != (len(d),) for s, d in zip(states, demos, strict=False)
        ):
            raise ValueError("export_lerobot: give one HSMM state per sample of each demonstration")
    return demos, states


def export_lerobot(path, demos, metadata=None, *, fps=None, hsmm_states=None, task=None,
                   data_files_size_in_mb=DATA_FILES_SIZE_IN_MB, chunks_size=CHUNKS_SIZE):
    """Write demonstrations to the folder ``path`` as a LeRobot v3.0 dataset, atomically.

    Parameters
    ----------
    path : path-like
        The dataset folder. Missing, empty, or a previous export by this tool (replaced);
        anything else is refused (ValueError) and left untouched.
    demos : sequence of Demonstration, at least one.
    metadata : dict, optional
        The dataset's metadata (``load_dataset``), kept in ``meta/hemg_drake.json``.
    fps : int, optional
        Frames per second (1 / the log period); by default from the sample times.
    hsmm_states : sequence of int arrays, optional
        Each demonstration's HSMM state per sample: adds the ``hsmm.state`` feature.
    task : str, optional
        The task text; by default from ``metadata["task"]``.
    data_files_size_in_mb, chunks_size : int
        LeRobot's file size limit and files per chunk (its defaults: 100 MB, 1000).

    Returns
    -------
    int, the number of frames written.
    """
    pa, pq = _pyarrow()
    demos, hsmm_states = _check_inputs(demos, hsmm_states)
    fps = check_fps(demos, fps)
    metadata = dict(metadata or {})
    task_name = metadata.get("task", "unknown")
    task = task or TASK_TEXT.get(task_name, str(task_name))
    try:
        metadata_text = json.dumps(metadata, sort_keys=True)
    except TypeError as error:
        raise ValueError(f"metadata must be JSON-serialisable: {error}") from None
    path = Path(path)
    check_output(path)
    quats = tool_quaternions(demos)  # None unless every demonstration has q and R_WE
    if quats is None:
        warnings.warn(NO_ARM_NOTE.format(keys="them: observation.state is [p_WE, v_WE]"),
                      stacklevel=2)  # fmt: skip
    spec = features(hsmm_states is not None, quats is not None)
    with _staged_folder(path) as stage:
        written = _write(stage, pa, pq, demos, spec, fps, task, hsmm_states, quats,
                         data_files_size_in_mb, chunks_size)  # fmt: skip
        marker = {
            "writer": WRITER, "hemg_drake": hemg_drake.__version__,
            "codebase_version": CODEBASE_VERSION, "lerobot_version": LEROBOT_VERSION,
            "cameras": "none: the simulated cell has no cameras, so the dataset has no videos",
            "seeds": [demo.seed for demo in demos], "metadata": json.loads(metadata_text),
            "files": sorted([*written, MARKER]),
        }  # fmt: skip
        _write_json(stage / MARKER, marker)
    return sum(len(demo) for demo in demos)


def _write(stage, pa, pq, demos, spec, fps, task, hsmm_states, quats, size_in_mb, chunks_size):
    written, episodes, all_columns = [], [], []
    chunk, file_, file_bytes, writer, first_index = 0, 0, 0, None, 0
    try:
        for c, demo in enumerate(demos):
            states = None if hsmm_states is None else hsmm_states[c]
            columns = _episode_columns(demo, c, first_index, fps, states,
                                       None if quats is None else quats[c])  # fmt: skip
            table = _table(pa, columns, spec)
            if writer is not None and file_bytes + table.nbytes > size_in_mb * 1024**2:
                writer.close()
                writer, file_bytes = None, 0
                chunk, file_ = (chunk + 1, 0) if file_ == chunks_size - 1 else (chunk, file_ + 1)
            if writer is None:
                name = DATA_PATH.format(chunk_index=chunk, file_index=file_)
                (stage / name).parent.mkdir(parents=True, exist_ok=True)
                writer = pq.ParquetWriter(stage / name, table.schema, compression="snappy")
                written.append(name)
            writer.write_table(table)
            file_bytes += table.nbytes
            stats = feature_stats_of(columns)
            episodes.append({
                "episode_index": c, "tasks": [task], "length": len(demo),
                "data/chunk_index": chunk, "data/file_index": file_,
                "dataset_from_index": first_index, "dataset_to_index": first_index + len(demo),
                "meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0,
                **{f"stats/{name}/{key}": value.tolist() for name, feature in stats.items()
                   for key, value in feature.items()},
            })  # fmt: skip
            all_columns.append(columns)
            first_index += len(demo)
    finally:
        if writer is not None:
            writer.close()
    episodes_name = EPISODES_PATH.format(chunk_index=0, file_index=0)
    (stage / episodes_name).parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.Table.from_pylist(episodes), stage / episodes_name, compression="snappy")
    _write_tasks(pa, pq, stage / TASKS_PATH, [task])
    merged = {name: np.concatenate([cols[name] for cols in all_columns]) for name in spec}
    _write_json(stage / "meta/stats.json", _stats_json(feature_stats_of(merged)))
    info = {
        "codebase_version": CODEBASE_VERSION, "robot_type": "baxter",
        "total_episodes": len(demos), "total_frames": first_index, "total_tasks": 1,
        "chunks_size": chunks_size, "data_files_size_in_mb": size_in_mb,
        "video_files_size_in_mb": VIDEO_FILES_SIZE_IN_MB, "fps": fps,
        "splits": {"train": f"0:{len(demos)}"}, "data_path": DATA_PATH, "video_path": None,
        "features": spec,
    }  # fmt: skip
    _write_json(stage / "meta/info.json", info)
    return [*written, episodes_name, TASKS_PATH, "meta/stats.json", "meta/info.json"]


def feature_stats_of(columns):
    """:func:`feature_stats` of every column (name -> (n, d) array)."""
    return {name: feature_stats(values) for name, values in columns.items()}


def _write_tasks(pa, pq, path, tasks):
    # pandas (LeRobot's reader) restores the column "task" as the frame's index.
    table = pa.table({"task_index": pa.array(range(len(tasks)), pa.int64()),
                      "task": pa.array(tasks, pa.string())})  # fmt: skip
    pandas_metadata = {
        "index_columns": ["task"],
        "column_indexes": [{"name": None, "field_name": None, "pandas_type": "unicode",
                            "numpy_type": "object", "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64",
             "numpy_type": "int64", "metadata": None},
            {"name": "task", "field_name": "task", "pandas_type": "unicode",
             "numpy_type": "object", "metadata": None},
        ],
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.0",
    }  # fmt: skip
    table = table.replace_schema_metadata({"pandas": json.dumps(pandas_metadata)})
    pq.write_table(table, path, compression="snappy")


def _write_json(path, data):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=4, ensure_ascii=False)
        f.write("\n")


# ------------------------------------------------------------ the folder, atomically
def previous_export(path):
    """The files a previous export wrote into ``path`` (its marker's list), or None if
    ``path`` is not a folder this tool exported to."""
    marker = Path(path) / MARKER
    try:
        record = json.loads(marker.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    files = record.get("files") if isinstance(record, dict) else None
    if record.get("writer") != WRITER or not isinstance(files, list):
        return None
    return files


def check_output(path):
    """Raise ValueError unless ``path`` may be (re)written: missing, an empty folder, or a
    previous export holding only the files it wrote."""
    path = Path(path)
    if not path.exists():
        return
    if not path.is_dir():
        raise ValueError(f"{path}: exists and is not a folder; a LeRobot dataset is a folder")
    present = sorted(str(p.relative_to(path)) for p in path.rglob("*") if not p.is_dir())
    if not present:
        return
    files = previous_export(path)
    if files is None:
        raise ValueError(
            f"{path}: holds files that are not a LeRobot export by hemg-drake (no "
            f"{MARKER}); give a new or empty folder"
        )
    extra = sorted(set(present) - set(files))
    if extra:
        raise ValueError(
            f"{path}: holds {extra[0]}, which the previous export did not write; move it "
            f"away or give another folder"
        )


@contextlib.contextmanager
def _staged_folder(path):
    """A temporary sibling folder of ``path``; renamed to ``path`` if the block succeeds,
    removed if it fails (OSError while writing: one line naming ``path``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(stage, 0o777 & ~mask)  # mkdtemp's 0700: give the mode mkdir would have
    try:
        try:
            yield stage
            _sync_tree(stage)
        except OSError as error:
            raise write_error(path, error) from None
        _swap_into_place(stage, path)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def _sync_tree(root):
    for folder, _, names in os.walk(root):
        for name in names:
            with open(os.path.join(folder, name), "rb") as f:
                os.fsync(f.fileno())


_RENAME_EXCHANGE = 2


def _exchange(a, b):
    """Swap two paths atomically (Linux renameat2 RENAME_EXCHANGE); False if unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd = -100
    result = renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE)
    if result == 0:
        return True
    number = ctypes.get_errno()
    if number in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(number, os.strerror(number), str(b))


def _swap_into_place(stage, path):
    if not path.exists() or not any(path.iterdir()):
        os.replace(stage, path)  # onto nothing, or onto an empty folder: atomic
        return
    if _exchange(stage, path):
        return  # the old export is now at ``stage``, removed by the caller
    old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
    os.replace(path, old / "dataset")
    try:
        os.replace(stage, path)
    except OSError:
        os.replace(old / "dataset", path)
        raise
    finally:
        shutil.rmtree(old, ignore_errors=True)
