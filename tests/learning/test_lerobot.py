"""LeRobot v3.0 export: read back with plain pyarrow, the format's schema, stats against numpy,
the folder written atomically and never over what the tool did not write."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")

from hemg_drake.learning.lerobot import MARKER, export_lerobot  # noqa: E402

METADATA = {"task": "cotter_pin", "log_period": 0.01}
LENGTHS = (40, 55, 12)
# LeRobot v3.0's layout (lerobot/datasets/utils.py of 0.4.x), written out independently.
INFO_KEYS = {
    "codebase_version", "robot_type", "total_episodes", "total_frames", "total_tasks",
    "chunks_size", "data_files_size_in_mb", "video_files_size_in_mb", "fps", "splits",
    "data_path", "video_path", "features",
}  # fmt: skip
EPISODE_COLUMNS = {
    "episode_index", "tasks", "length", "data/chunk_index", "data/file_index",
    "dataset_from_index", "dataset_to_index", "meta/episodes/chunk_index",
    "meta/episodes/file_index",
}  # fmt: skip
STATS = {"min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"}
# observation.state's entries, written out: the arm's joints, the tool's pose, its velocity.
STATE_NAMES = [
    "right_s0", "right_s1", "right_e0", "right_e1", "right_w0", "right_w1", "right_w2",
    "p_WE_x", "p_WE_y", "p_WE_z", "quat_WE_w", "quat_WE_x", "quat_WE_y", "quat_WE_z",
    "v_WE_x", "v_WE_y", "v_WE_z",
]  # fmt: skip
QUAT = slice(10, 14)


@pytest.fixture
def demos(make_demo):
    return [make_demo(3 + c, n) for c, n in enumerate(LENGTHS)]


def _data(root):
    files = sorted((root / "data").glob("chunk-*/file-*.parquet"))
    return pa.concat_tables([pq.read_table(f) for f in files])


def _column(table, name):
    """A column as a numpy array (n, d), fixed-size lists unpacked by hand."""
    column = table.column(name).combine_chunks()
    if pa.types.is_fixed_size_list(column.type):
        return np.asarray(column.flatten()).reshape(len(column), column.type.list_size)
    return np.asarray(column)[:, None]


def _expected(demos, states=None):
    """What each column must hold, built from the demonstrations field by field."""
    cat = lambda *fields: np.concatenate([np.column_stack([getattr(d, f) for f in fields])
                                          for d in demos])  # noqa: E731  # fmt: skip
    frame = np.concatenate([np.arange(len(d)) for d in demos])
    # observation.state but its quaternion (checked by split_state).
    state = cat("q", "p_WE", "v_WE") if demos[0].q is not None else cat("p_WE", "v_WE")
    expected = {
        "observation.state": state, "observation.force": cat("f_WE"),
        "action": cat("p_WE_desired", "gain"), "operator.emg_envelope": cat("envelope"),
        "operator.activation": cat("activation"), "operator.p_MS": cat("p_MS"),
        "frame_index": frame[:, None],
        "episode_index": np.concatenate([[c] * len(d) for c, d in enumerate(demos)])[:, None],
        "index": np.arange(len(frame))[:, None], "task_index": np.zeros((len(frame), 1)),
    }  # fmt: skip
    if states is not None:
        expected["hsmm.state"] = np.concatenate(states)[:, None]
    return expected


def split_state(state, demos, rotation):
    """observation.state without its quaternion [w, x, y, z], the quaternion checked against
    the demonstrations' R_WE by the closed-form matrix of each (float32: to 1e-6)."""
    quats = np.asarray(state[:, QUAT], dtype=np.float64)
    np.testing.assert_allclose(np.linalg.norm(quats, axis=1), 1.0, atol=1e-6)
    R_WE = np.concatenate([demo.R_WE for demo in demos])
    np.testing.assert_allclose(rotation(quats), R_WE, atol=2e-6)
    return np.delete(state, np.arange(state.shape[1])[QUAT], axis=1)


def test_round_trip_every_column_dtype_and_shape(tmp_path, demos, quaternion_rotation):
    states = [np.arange(n) % 4 for n in LENGTHS]
    root = tmp_path / "lerobot"
    assert export_lerobot(root, demos, METADATA, fps=100, hsmm_states=states) == sum(LENGTHS)
    table = _data(root)
    info = json.loads((root / "meta/info.json").read_text())
    assert set(table.column_names) == set(info["features"])
    for name, values in _expected(demos, states).items():
        feature = info["features"][name]
        got = _column(table, name)
        assert got.shape == (sum(LENGTHS), *feature["shape"]), name
        assert got.dtype == np.dtype(feature["dtype"]), name
        if name == "observation.state":
            assert feature["shape"] == [17] and feature["names"] == STATE_NAMES
            got = split_state(got, demos, quaternion_rotation)
        want = values.astype(feature["dtype"])  # float32: LeRobot's policies' dtype
        np.testing.assert_array_equal(got, want, err_msg=name)
    # timestamp = frame_index / fps exactly: the float32 of the double quotient.
    frame = _column(table, "frame_index")[:, 0]
    timestamp = _column(table, "timestamp")[:, 0]
    assert timestamp.dtype == np.float32
    assert np.array_equal(timestamp, np.array([np.float32(int(i) / 100) for i in frame]))


def test_a_dataset_without_joints_exports_as_before_with_a_warning(tmp_path, make_demo):
    old = [make_demo(3 + c, n, arm=False) for c, n in enumerate(LENGTHS)]
    root = tmp_path / "lerobot"
    with pytest.warns(UserWarning, match="exported without them: observation.state is"):
        export_lerobot(root, old, METADATA, fps=100)
    info = json.loads((root / "meta/info.json").read_text())
    state = info["features"]["observation.state"]
    assert state["shape"] == [6] and state["names"] == [*STATE_NAMES[7:10], *STATE_NAMES[14:]]
    np.testing.assert_array_equal(_column(_data(root), "observation.state"),
                                  _expected(old)["observation.state"].astype(np.float32))  # fmt: skip
    stats = json.loads((root / "meta/stats.json").read_text())
    assert len(stats["observation.state"]["mean"]) == 6


def test_files_follow_the_v3_schema(tmp_path, demos):
    root = tmp_path / "lerobot"
    export_lerobot(root, demos, METADATA, fps=100)
    info = json.loads((root / "meta/info.json").read_text())
    assert set(info) == INFO_KEYS
    assert info["codebase_version"] == "v3.0" and info["fps"] == 100
    assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
    assert info["video_path"] is None  # no cameras
    assert not [f for f in info["features"].values() if f["dtype"] in ("video", "image")]
    assert (info["total_episodes"], info["total_frames"], info["total_tasks"]) == (3, 107, 1)
    assert info["splits"] == {"train": "0:3"}
    for name in ("timestamp", "frame_index", "episode_index", "index", "task_index"):
        assert info["features"][name]["shape"] == [1]
    assert not (root / "videos").exists()
    # Every file the format names, and no other (the tool's own marker aside).
    files = sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())
    assert files == ["data/chunk-000/file-000.parquet", "meta/episodes/chunk-000/file-000.parquet",
                     MARKER, "meta/info.json", "meta/stats.json", "meta/tasks.parquet"]  # fmt: skip
    tasks = pq.read_table(root / "meta/tasks.parquet")
    assert tasks.column("task").to_pylist() == ["pull the cotter pin out of its hole"]
    assert tasks.column("task_index").to_pylist() == [0]
    pandas_meta = json.loads(tasks.schema.metadata[b"pandas"])  # pandas makes "task" the index
    assert pandas_meta["index_columns"] == ["task"]
    episodes = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    assert EPISODE_COLUMNS <= set(episodes[0])
    start = 0
    for c, (episode, n) in enumerate(zip(episodes, LENGTHS, strict=True)):
        assert episode["episode_index"] == c and episode["length"] == n
        assert (episode["dataset_from_index"], episode["dataset_to_index"]) == (start, start + n)
        assert (episode["data/chunk_index"], episode["data/file_index"]) == (0, 0)
        assert episode["tasks"] == ["pull the cotter pin out of its hole"]
        start += n
    data_schema = pq.read_schema(root / info["data_path"].format(chunk_index=0, file_index=0))
    assert data_schema.field("timestamp").type == pa.float32()
    assert data_schema.field("action").type.list_size == 4


def test_stats_agree_with_numpy(tmp_path, demos):
    root = tmp_path / "lerobot"
    export_lerobot(root, demos, METADATA, fps=100)
    stats = json.loads((root / "meta/stats.json").read_text())
    table = _data(root)
    info = json.loads((root / "meta/info.json").read_text())
    assert set(stats) == set(info["features"])
    for name, feature in stats.items():
        assert set(feature) == STATS, name
        values = _column(table, name).astype(np.float64)
        np.testing.assert_allclose(feature["mean"], values.mean(axis=0), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(feature["std"], values.std(axis=0), rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(feature["min"], values.min(axis=0))
        np.testing.assert_array_equal(feature["max"], values.max(axis=0))
        assert feature["count"] == [len(values)]
        # q50 by hand: the middle of the sorted values (107 frames: the 54th).
        np.testing.assert_array_equal(feature["q50"], np.sort(values, axis=0)[53])
    # Each episode's own stats, in its row of the episodes file.
    episodes = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    state = _column(table, "observation.state").astype(np.float64)
    np.testing.assert_allclose(episodes[1]["stats/observation.state/mean"],
                               state[40:95].mean(axis=0), rtol=1e-12)  # fmt: skip
    assert episodes[2]["stats/action/count"] == [12]


def test_episodes_are_chunked_into_files_by_size(tmp_path, make_demo):
    # 1 MB per file at ~100 bytes per frame: three 5000-frame episodes need two files.
    demos = [make_demo(c, 5000) for c in range(3)]
    root = tmp_path / "lerobot"
    export_lerobot(root, demos, METADATA, fps=100, data_files_size_in_mb=1, chunks_size=1)
    episodes = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    where = [(e["data/chunk_index"], e["data/file_index"]) for e in episodes]
    assert where[0] == (0, 0) and where[-1] != (0, 0)
    assert len(set(where)) >= 2
    for episode in episodes:  # an episode lives whole in its file, rows by dataset index
        path = root / f"data/chunk-{episode['data/chunk_index']:03d}/file-" \
                      f"{episode['data/file_index']:03d}.parquet"  # fmt: skip
        index = pq.read_table(path).column("index").to_numpy()
        rows = index[(index >= episode["dataset_from_index"]) & (index < episode["dataset_to_index"])]
        assert len(rows) == episode["length"]


def test_refuses_a_folder_it_did_not_write_and_replaces_its_own(tmp_path, demos):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "notes.txt").write_text("keep me")
    with pytest.raises(ValueError, match="not a LeRobot export by hemg-drake"):
        export_lerobot(user, demos, METADATA, fps=100)
    assert [p.name for p in user.iterdir()] == ["notes.txt"]
    root = tmp_path / "lerobot"
    export_lerobot(root, demos[:1], METADATA, fps=100)
    export_lerobot(root, demos, METADATA, fps=100)  # a previous export: replaced
    assert json.loads((root / "meta/info.json").read_text())["total_episodes"] == 3
    (root / "meta/mine.txt").write_text("added by hand")
    with pytest.raises(ValueError, match="meta/mine.txt, which the previous export did not"):
        export_lerobot(root, demos[:1], METADATA, fps=100)
    assert json.loads((root / "meta/info.json").read_text())["total_episodes"] == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lerobot", "mine"]  # no temporaries


def test_a_failure_midway_leaves_the_previous_export(tmp_path, demos, monkeypatch):
    from hemg_drake.learning import lerobot

    root = tmp_path / "lerobot"
    export_lerobot(root, demos[:1], METADATA, fps=100)
    before = {p: p.read_bytes() for p in root.rglob("*") if p.is_file()}

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(lerobot, "_write_tasks", full)
    with pytest.raises(OSError, match="cannot write it: No space left on device") as error:
        export_lerobot(root, demos, METADATA, fps=100)
    assert error.value.filename == str(root)
    assert {p: p.read_bytes() for p in root.rglob("*") if p.is_file()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lerobot"]


def test_fps_must_match_the_sample_times(tmp_path, demos):
    with pytest.raises(ValueError, match="not sampled every 1/50 s"):
        export_lerobot(tmp_path / "x", demos, METADATA, fps=50)
    with pytest.raises(ValueError, match="whole number of frames per second"):
        export_lerobot(tmp_path / "x", demos, METADATA, fps=33.3)
    assert not (tmp_path / "x").exists()
    export_lerobot(tmp_path / "x", demos, METADATA)  # found from the sample times: 100
    assert json.loads((tmp_path / "x/meta/info.json").read_text())["fps"] == 100


LEROBOT_PYTHON = os.environ.get("HEMG_LEROBOT_PYTHON", "/tmp/lerobot_venv/bin/python")


def _lerobot_python():
    if not Path(LEROBOT_PYTHON).exists():
        return None
    probe = subprocess.run([LEROBOT_PYTHON, "-c", "import lerobot, pyarrow, torch"],
                           capture_output=True, timeout=300)  # fmt: skip
    return LEROBOT_PYTHON if probe.returncode == 0 else None


@pytest.mark.slow
def test_lerobot_itself_loads_the_dataset(tmp_path, demos, quaternion_rotation):
    """Where the ``lerobot`` package runs (a Python named by HEMG_LEROBOT_PYTHON; it needs
    torch): LeRobotDataset reads the export, frame for frame."""
    python = _lerobot_python()
    if python is None:
        pytest.skip("no Python with lerobot (set HEMG_LEROBOT_PYTHON)")
    root = tmp_path / "lerobot"
    states = [np.arange(n) % 4 for n in LENGTHS]
    export_lerobot(root, demos, METADATA, fps=100, hsmm_states=states)
    script = f"""
import importlib.machinery, json, sys, types, numpy as np
try:
    import torchvision  # noqa: F401
except (ImportError, RuntimeError):
    # A torchvision built against another torch: LeRobot uses it only for images, and
    # this dataset has none, so an empty stand-in lets its reader import.
    stub = types.ModuleType("torchvision")
    stub.transforms = types.ModuleType("torchvision.transforms")
    for module in (stub, stub.transforms):
        module.__spec__ = importlib.machinery.ModuleSpec(module.__name__, None)
    sys.modules.update({{"torchvision": stub, "torchvision.transforms": stub.transforms}})
from lerobot.datasets.lerobot_dataset import LeRobotDataset
ds = LeRobotDataset("local/hemg_drake", root={str(root)!r})
item = ds[45]
print(json.dumps({{"len": len(ds), "episodes": ds.num_episodes, "fps": ds.fps,
    "task": item["task"], "state": item["observation.state"].tolist(),
    "action": item["action"].tolist(), "hsmm": int(item["hsmm.state"]),
    "timestamp": float(item["timestamp"]), "episode": int(item["episode_index"]),
    "action_mean": np.asarray(ds.meta.stats["action"]["mean"]).tolist()}}))
"""
    env = dict(os.environ, HF_HUB_OFFLINE="1", HF_DATASETS_CACHE=str(tmp_path / "cache"))
    result = subprocess.run([python, "-c", script], capture_output=True, text=True,
                            timeout=600, env=env)  # fmt: skip
    assert result.returncode == 0, result.stderr[-2000:]
    got = json.loads(result.stdout.strip().splitlines()[-1])
    assert (got["len"], got["episodes"], got["fps"]) == (sum(LENGTHS), 3, 100)
    assert got["task"] == "pull the cotter pin out of its hole"
    demo = demos[1]  # frame 45 of the dataset: frame 5 of episode 1
    frame5 = SimpleNamespace(R_WE=demo.R_WE[5:6])
    state = split_state(np.float32([got["state"]]), [frame5], quaternion_rotation)
    np.testing.assert_array_equal(state[0], np.float32(np.r_[demo.q[5], demo.p_WE[5], demo.v_WE[5]]))
    np.testing.assert_array_equal(
        np.float32(got["action"]), np.float32(np.r_[demo.p_WE_desired[5], demo.gain[5]]))
    assert (got["hsmm"], got["episode"]) == (5 % 4, 1)
    assert got["timestamp"] == float(np.float32(0.05))


def _run_folder(tmp_path, demos):
    from hemg_drake.learning.demos import save_dataset
    from hemg_drake.run_folder import RunFolder
    from hemg_drake.scenario import shipped_scenario

    folder = RunFolder(tmp_path / "run", create=True)
    text = shipped_scenario("cotter_pin").read_text(encoding="utf-8")
    save_dataset(folder.dataset, demos, {"task": "cotter_pin", "scenario": text})
    folder.finish("demonstrate", [folder.dataset])
    return folder


def test_cli_adds_hsmm_states_only_from_a_model_of_this_dataset(tmp_path, demos, capsys):
    from hemg_drake.cli import main
    from hemg_drake.learning.tphsmm import load_model
    from hemg_drake.pipeline import fit_model, learning_data, load_demonstrations

    folder = _run_folder(tmp_path, demos)
    loaded, scenario = load_demonstrations(folder.dataset)
    data = learning_data(loaded, scenario)
    fit_model(data, scenario.replaced(["learning.num_states=2"]), n_iter=3).save(folder.model)
    folder.finish("learn", [folder.model], inputs=[folder.dataset])
    out = tmp_path / "lerobot"
    assert main(["export", str(folder.path), "--format", "lerobot", str(out)]) == 0
    assert capsys.readouterr().out == f"wrote {out} (3 demonstrations, 107 samples, HSMM states, lerobot)\n"
    table = _data(out)
    model = load_model(folder.model)
    want = np.concatenate([model.decode(demo)[1] for demo in data])
    np.testing.assert_array_equal(_column(table, "hsmm.state")[:, 0], want)
    assert set(np.unique(want)) <= {0, 1}
    info = json.loads((out / "meta/info.json").read_text())
    assert info["features"]["hsmm.state"]["dtype"] == "int64" and info["fps"] == 100
    # The dataset recorded again, the model not learnt again: no states (they would be
    # another dataset's), and the folder export replaces its own previous one.
    _run_folder(tmp_path, demos[:2])
    assert main(["export", str(folder.path), "--format", "lerobot", str(out)]) == 0
    assert "hsmm.state" not in _data(out).column_names
    assert json.loads((out / "meta/info.json").read_text())["total_episodes"] == 2


def test_cli_refuses_a_user_folder_in_one_line(tmp_path, demos, capsys):
    from hemg_drake.cli import main

    folder = _run_folder(tmp_path, demos)
    assert main(["export", str(folder.path), "--format", "lerobot", str(folder.path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a LeRobot export by hemg-drake" in err
    assert sorted(p.name for p in folder.path.iterdir()) == ["dataset.npz", "manifest.json"]
