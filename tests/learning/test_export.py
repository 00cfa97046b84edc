"""robomimic export: a round trip, the layout as robomimic reads it, and the CLI."""

import dataclasses
import json

import numpy as np
import pytest

from hemg_drake.cli import main
from hemg_drake.learning.demos import save_dataset
from hemg_drake.learning.export import export_robomimic, load_robomimic

h5py = pytest.importorskip("h5py")


@pytest.fixture
def demos(make_demo):
    return [make_demo(3, 40), make_demo(4, 55), make_demo(5, 12)]


METADATA = {"task": "cotter_pin", "log_period": 0.01, "scenario": "task: cotter_pin\n"}


def test_round_trip_gives_the_same_arrays(tmp_path, demos):
    path = tmp_path / "demos.hdf5"
    assert export_robomimic(path, demos, METADATA) == 40 + 55 + 12
    loaded, metadata = load_robomimic(path)
    assert metadata == METADATA
    assert len(loaded) == len(demos)
    for original, back in zip(demos, loaded):
        assert back.seed == original.seed
        for field in ("time", "p_WE", "v_WE", "p_MS", "p_WE_desired", "envelope", "activation",
                      "gain", "f_WE", "emg_time", "emg", "muscle_activation", "q",
                      "R_WE"):  # fmt: skip
            np.testing.assert_array_equal(getattr(back, field), getattr(original, field))


def test_a_dataset_without_joints_exports_as_before_with_a_warning(tmp_path, make_demo):
    old = [make_demo(3, 40, arm=False), make_demo(4, 55, arm=False)]
    path = tmp_path / "old.hdf5"
    with pytest.warns(UserWarning, match="exported without robot0_joint_pos, robot0_eef_pos"):
        export_robomimic(path, old, METADATA)
    with h5py.File(path, "r") as f:
        assert set(f["data/demo_0/obs"]) == {"p_WE", "v_WE", "p_MS", "f_WE", "gain", "envelope",
                                             "activation"}  # fmt: skip
        assert "R_WE" not in f["data/demo_0"]
        assert "robot0_eef_quat" not in json.loads(f["data"].attrs["env_args"])["env_kwargs"]["obs_keys"]
    loaded, _ = load_robomimic(path)
    assert loaded[1].q is None and loaded[1].R_WE is None
    np.testing.assert_array_equal(loaded[1].p_WE, old[1].p_WE)


def test_task_frames_of_placed_demonstrations_make_the_round_trip(tmp_path, demos):
    rng = np.random.default_rng(7)
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    placed = [
        dataclasses.replace(demo, frame_A=np.stack([np.eye(3), rotation]),
                            frame_b=np.array([[0.0, 0.0, 0.0], rng.normal(size=3)]))
        for demo in demos[:2]
    ] + demos[2:]  # fmt: skip
    path = tmp_path / "placed.hdf5"
    export_robomimic(path, placed, METADATA)
    loaded, _ = load_robomimic(path)
    for original, back in zip(placed[:2], loaded[:2]):
        np.testing.assert_array_equal(back.frame_A, original.frame_A)
        np.testing.assert_array_equal(back.frame_b, original.frame_b)
    assert loaded[2].frame_A is None and loaded[2].frame_b is None  # one placement: none
    with h5py.File(path, "r") as f:
        assert f["data/demo_1/task_frames/A"].shape == (2, 3, 3)
        assert "task_frames" not in f["data/demo_2"]
    # A damaged file: one half of the frames gone, or frames of the wrong shape.
    with h5py.File(path, "r+") as f:
        del f["data/demo_0/task_frames/b"]
    with pytest.raises(ValueError, match=r"demo_0/task_frames/b is missing"):
        load_robomimic(path)
    with h5py.File(path, "r+") as f:
        f["data/demo_0/task_frames/b"] = np.zeros((3, 3))
    with pytest.raises(ValueError, match=r"demo_0: .*frame_A', 'frame_b' must have shapes"):
        load_robomimic(path)


def test_file_has_robomimics_layout_read_with_plain_h5py(tmp_path, demos, quaternion_rotation):
    path = tmp_path / "demos.hdf5"
    export_robomimic(path, demos, METADATA)
    # Read as robomimic's SequenceDataset and file utilities do: demos sorted by the
    # integer after "demo_", num_samples per demo, obs/<key> (N, D), actions (N, A).
    with h5py.File(path, "r") as f:
        data = f["data"]
        names = sorted(data.keys(), key=lambda name: int(name[5:]))
        assert names == ["demo_0", "demo_1", "demo_2"]
        assert int(data.attrs["total"]) == sum(len(d) for d in demos)
        env_meta = json.loads(data.attrs["env_args"])
        assert env_meta["env_name"] == "hemg_drake/cotter_pin"
        assert env_meta["type"] == 2 and isinstance(env_meta["env_kwargs"], dict)
        for name, demo in zip(names, demos):
            group = data[name]
            n = int(group.attrs["num_samples"])
            assert n == len(demo)
            widths = {"p_WE": 3, "v_WE": 3, "p_MS": 3, "f_WE": 3, "gain": 1, "envelope": 1,
                      "activation": 1, "robot0_joint_pos": 7, "robot0_eef_pos": 3,
                      "robot0_eef_quat": 4}  # fmt: skip
            assert set(env_meta["env_kwargs"]["obs_keys"]) == set(widths)
            assert set(group["obs"].keys()) == set(widths)
            assert set(group["next_obs"].keys()) == set(widths)
            for key, width in widths.items():
                assert group[f"obs/{key}"].shape == (n, width)
                assert group[f"next_obs/{key}"].shape == (n, width)
            np.testing.assert_array_equal(group["obs/p_WE"][()], demo.p_WE)
            np.testing.assert_array_equal(group["obs/gain"][()][:, 0], demo.gain)
            np.testing.assert_array_equal(group["next_obs/v_WE"][()][:-1], demo.v_WE[1:])
            np.testing.assert_array_equal(group["next_obs/v_WE"][()][-1], demo.v_WE[-1])
            np.testing.assert_array_equal(group["obs/robot0_joint_pos"][()], demo.q)
            np.testing.assert_array_equal(group["obs/robot0_eef_pos"][()], demo.p_WE)
            # robosuite's quaternion order, [x, y, z, w]: unit, and the tool's rotation.
            x, y, z, w = group["obs/robot0_eef_quat"][()].T
            np.testing.assert_allclose(x**2 + y**2 + z**2 + w**2, 1.0, atol=1e-14)
            rotation = quaternion_rotation(np.column_stack([w, x, y, z]))
            np.testing.assert_allclose(rotation, demo.R_WE, atol=1e-14)
            actions = group["actions"][()]
            assert actions.shape == (n, 4)
            np.testing.assert_array_equal(actions[:, :3], demo.p_WE_desired)
            np.testing.assert_array_equal(actions[:, 3], demo.gain)
            assert group["rewards"].shape == (n,) and not np.any(group["rewards"][()])
            dones = group["dones"][()]
            assert dones.shape == (n,) and dones[-1] == 1 and not np.any(dones[:-1])


def test_export_is_atomic_and_bad_input_is_named(tmp_path, demos):
    path = tmp_path / "demos.hdf5"
    path.write_bytes(b"old")
    with pytest.raises(ValueError, match="JSON-serialisable"):
        export_robomimic(path, demos, {"bad": object()})
    with pytest.raises(ValueError, match="non-empty list of Demonstration"):
        export_robomimic(path, [], METADATA)
    assert path.read_bytes() == b"old" and list(tmp_path.iterdir()) == [path]
    with pytest.raises(ValueError, match="not a readable HDF5 file"):
        load_robomimic(path)
    with pytest.raises(FileNotFoundError, match="robomimic file not found"):
        load_robomimic(tmp_path / "missing.hdf5")
    with h5py.File(tmp_path / "other.hdf5", "w") as f:
        f.create_group("data")
    with pytest.raises(ValueError, match="not exported by hemg_drake"):
        load_robomimic(tmp_path / "other.hdf5")


def test_cli_exports_a_run_folder(tmp_path, demos, capsys):
    run = tmp_path / "run"
    run.mkdir()
    save_dataset(run / "dataset.npz", demos, METADATA)
    out = tmp_path / "out" / "pin.hdf5"
    assert main(["export", str(run), "--format", "robomimic", str(out)]) == 0
    assert "3 demonstrations, 107 samples" in capsys.readouterr().out
    loaded, metadata = load_robomimic(out)
    np.testing.assert_array_equal(loaded[1].p_WE, demos[1].p_WE)
    assert metadata["num_demonstrations"] == 3 and metadata["task"] == "cotter_pin"
    assert main(["export", str(tmp_path / "nowhere"), "--format", "robomimic", str(out)]) == 2
    assert "nowhere" in capsys.readouterr().err


def test_cli_imports_into_a_run_folder_that_learn_accepts(tmp_path, demos, capsys):
    from hemg_drake.learning.demos import load_dataset
    from hemg_drake.run_folder import RunFolder

    path = tmp_path / "demos.hdf5"
    export_robomimic(path, demos, METADATA)
    run = tmp_path / "imported"
    assert main(["import", str(path), "--out", str(run)]) == 0
    assert "3 demonstrations" in capsys.readouterr().out
    folder = RunFolder(run)
    folder.check("demonstrate", folder.dataset, run_hint="hemg-drake import")  # recorded
    loaded, metadata = load_dataset(folder.dataset)
    np.testing.assert_array_equal(loaded[2].emg, demos[2].emg)
    assert metadata["scenario"] == METADATA["scenario"] and metadata["imported_from"] == str(path)
    # A bad file leaves no run folder behind.
    (tmp_path / "junk.hdf5").write_bytes(b"junk")
    assert main(["import", str(tmp_path / "junk.hdf5"), "--out", str(tmp_path / "new")]) == 2
    assert "not a readable HDF5 file" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()
