"""A model knows where it was learnt (issue 23): the scene placements in model.npz, older
files without them still load, and a world-frame model reproduced at another placement
warns (the CLI: one line on stderr)."""

import json
import warnings

import numpy as np
import pytest

from hemg_drake.cli import main
from hemg_drake.learning.hsmm import HSMM
from hemg_drake.learning.tphsmm import TaskParameterisedHSMM, load_model
from hemg_drake.placements import check_learnt_placement, scene_placements
from hemg_drake.scenario import load_scenario, shipped_scenario

SHIPPED_RING = [0.642, -0.837, 0.12]  # the shipped pin scene's position (cotter_pin.yaml)


def _yaw(deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _frames(position, yaw_deg):
    return np.stack([np.eye(3), _yaw(yaw_deg)]), np.stack([np.zeros(3), position])


def _data(seed):
    t = np.linspace(0, 1, 80)[:, None]
    rng = np.random.default_rng(seed)
    x = np.hstack([np.sin(3 * t + c) for c in range(3)]) + 0.01 * rng.standard_normal((80, 3))
    return np.hstack([x, np.gradient(x, axis=0) * 80, 100 + 10 * t])


def test_the_placements_are_saved_with_the_model_and_older_files_still_load(tmp_path):
    frames = [_frames([0.6, -0.8, 0.1], 0.0), _frames([0.6, -0.8, 0.1], 0.0),
              _frames([0.65, -0.8, 0.1], 20.0)]  # fmt: skip
    learnt_at = scene_placements(frames)
    # Two distinct placements, in order, as the scene frame's position and rotation.
    assert [e["position"] for e in learnt_at] == [[0.6, -0.8, 0.1], [0.65, -0.8, 0.1]]
    np.testing.assert_allclose(learnt_at[1]["rotation"], _yaw(20.0), atol=1e-15)
    data = [_data(1), _data(2), _data(3)]
    plain = HSMM(3, init="time", n_iter=2).fit(data)
    scene = [(A[1:], b[1:]) for A, b in frames]
    task = TaskParameterisedHSMM(3, init="time", n_iter=2).fit(data, scene)
    for name, model in (("plain.npz", plain), ("tp.npz", task)):
        model.save(tmp_path / f"old_{name}")  # written without placements (before issue 23)
        model.learnt_at_ = learnt_at
        model.save(tmp_path / name)
        assert load_model(tmp_path / name).learnt_at_ == learnt_at
        assert load_model(tmp_path / f"old_{name}").learnt_at_ is None
        with np.load(tmp_path / f"old_{name}") as arrays:
            assert "learnt_at" not in arrays.files
    with np.load(tmp_path / "plain.npz") as arrays:
        damaged = {**dict(arrays), "learnt_at": np.array("[{not json")}
    np.savez(tmp_path / "damaged.npz", **damaged)
    with pytest.raises(ValueError, match="damaged.npz: damaged model file, learnt_at"):
        load_model(tmp_path / "damaged.npz")


def test_a_world_frame_model_away_from_where_it_was_learnt_is_named():
    scenario = load_scenario(shipped_scenario("cotter_pin"))
    position = scenario.X_WT().translation()
    np.testing.assert_allclose(position, SHIPPED_RING, atol=1e-12)
    learnt_at = scene_placements([_frames(position, 0.0)])
    model = HSMM(3)
    assert check_learnt_placement(model, scenario) is None  # unknown: nothing to say
    model.learnt_at_ = learnt_at
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert check_learnt_placement(model, scenario) is None  # where it was learnt
    for moved in (["scene.position=[0.652,-0.837,0.12]"], ["scene.yaw_deg=13.0"]):
        with pytest.warns(UserWarning, match="world-frame HSMM learnt with the scene at "
                                             r"\[0.642, -0.837, 0.12\] m, yaw 0.0 deg"):
            check_learnt_placement(model, scenario.replaced(moved), source="model.npz")
        # A file without placements: those of the demonstrations it was learnt from.
        with pytest.warns(UserWarning, match="world-frame HSMM"):
            check_learnt_placement(HSMM(3), scenario.replaced(moved), [_frames(position, 0.0)])
    # A TP-HSMM is placed by its frames.
    tp = TaskParameterisedHSMM(3)
    tp.learnt_at_ = learnt_at
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert check_learnt_placement(tp, scenario.replaced(moved)) is None


def test_reproducing_a_world_frame_model_at_a_moved_scene_warns_in_one_line(tmp_path, run_cli):
    small = ["--demos", "2", "--duration", "1", "--no-replay", "--set", "learning.n_iter=5"]
    assert main(["demonstrate", "cotter_pin", "--out", str(tmp_path), *small]) == 0
    assert main(["learn", str(tmp_path)]) == 0
    learnt = load_model(tmp_path / "model.npz")
    assert type(learnt) is HSMM
    np.testing.assert_allclose(learnt.learnt_at_[0]["position"], SHIPPED_RING, atol=1e-12)
    np.testing.assert_array_equal(learnt.learnt_at_[0]["rotation"], np.eye(3))
    # Where it was learnt: no warning.
    code, _, err = run_cli(["reproduce", str(tmp_path), "--no-replay"])
    assert code == 0 and "warning" not in err
    # Moved 2 cm and turned: one line on stderr, and the metrics are those of the new scene.
    moved = ["--set", "scene.position=[0.662,-0.837,0.12]", "--set", "scene.yaw_deg=10"]
    code, _, err = run_cli(["reproduce", str(tmp_path), "--no-replay", *moved])
    assert code == 0
    lines = [line for line in err.splitlines() if "warning" in line]
    assert len(lines) == 1 and lines[0].startswith("hemg-drake reproduce: warning: ")
    assert "world-frame HSMM" in lines[0] and "yaw 10.0 deg" in lines[0]
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["scene_position"] == pytest.approx([0.662, -0.837, 0.12])
    assert metrics["scene_yaw_deg"] == 10.0
