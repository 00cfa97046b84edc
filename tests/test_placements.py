"""Demonstrations at many placements (issue 16): poses drawn per seed within reach, task
frames in the dataset (format 3; format 2 still loads), a TP-HSMM learnt from them and a
reproduction at a new placement, end to end at small scale."""

import json

import numpy as np
import pytest

from hemg_drake.learning import demos as demos_module
from hemg_drake.learning.demos import load_dataset, save_dataset
from hemg_drake.learning.tphsmm import TaskParameterisedHSMM, load_model
from hemg_drake.pipeline import demonstrate, learn, reproduce
from hemg_drake.placements import (
    demonstration_scenario,
    draw_pose,
    moved_demonstration,
    task_frames,
)
from hemg_drake.scenario import load_scenario, shipped_scenario

RANGES = [
    "scene.placements.position_range=[[0.62,-0.86,0.11],[0.67,-0.81,0.13]]",
    "scene.placements.yaw_range_deg=[-20,20]",
]
SMALL = ["num_demonstrations=3", "duration=1.0", "learning.n_iter=5"]


def quiet(line):
    pass


def pin(*overrides):
    return load_scenario(shipped_scenario("cotter_pin"), overrides=[*SMALL, *overrides])


def test_a_placement_is_drawn_deterministically_per_seed_within_the_ranges():
    scenario = pin(*RANGES)
    poses = [draw_pose(scenario, seed) for seed in (1, 2, 3)]
    assert poses == [draw_pose(scenario, seed) for seed in (1, 2, 3)]  # same seed, same pose
    assert len({yaw for _, yaw in poses}) == 3  # each seed its own
    for position, yaw in poses:
        assert np.all(np.array(position) >= [0.62, -0.86, 0.11])
        assert np.all(np.array(position) <= [0.67, -0.81, 0.13])
        assert -20 <= yaw <= 20
    placed = demonstration_scenario(scenario, 2)
    np.testing.assert_array_equal(placed.scene.position, poses[1][0])  # exact round trip
    assert placed.scene.yaw_deg == poses[1][1]
    A, b = task_frames(placed)
    np.testing.assert_array_equal(A[0], np.eye(3))
    np.testing.assert_allclose(A[1], placed.X_WT().rotation().matrix(), atol=0)
    np.testing.assert_array_equal(b[1], poses[1][0])
    # The plan is in the scene: the ring (first waypoint) where the pose puts it.
    np.testing.assert_allclose(placed.task_plan().points[0], poses[1][0], atol=1e-15)
    # Without placements, every demonstration at the scenario's own pose.
    assert demonstration_scenario(pin(), 5) is not None
    assert demonstration_scenario(pin(), 5).scene.position == pin().scene.position


def test_an_unreachable_range_is_refused_before_anything_is_written(tmp_path):
    far = pin("scene.placements.position_range=[[1.5,0.0,0.1],[1.6,0.1,0.1]]")
    with pytest.raises(ValueError, match=r"scene.placements: no placement the arm can reach"):
        demonstrate(far, tmp_path / "run", replays=False, progress=quiet)
    assert not (tmp_path / "run").exists() or not any((tmp_path / "run").iterdir())
    with pytest.raises(ValueError, match="position_range' must be"):
        pin("scene.placements.position_range=[[0.7,-0.8,0.1],[0.6,-0.9,0.1]]")
    with pytest.raises(ValueError, match="yaw_range_deg' must be"):
        pin("scene.placements.yaw_range_deg=[10,-10]")


def _demo(seed, frames=None):
    rng = np.random.default_rng(seed)
    t = 4
    fields = {name: rng.standard_normal((t, w) if w > 1 else t)
              for name, w in demos_module.FIELD_WIDTHS.items()}  # fmt: skip
    fields["time"] = np.arange(t) * 0.01
    fields.update(emg_time=np.arange(2) / 200.0, emg=rng.standard_normal((2, 8)),
                  muscle_activation=np.zeros(2))  # fmt: skip
    if frames is not None:
        fields.update(frame_A=frames[0], frame_b=frames[1])
    return demos_module.Demonstration(seed=seed, **fields)


def test_dataset_frames_round_trip_and_format_2_still_loads(tmp_path):
    frames = task_frames(pin("scene.yaw_deg=30"))
    demos = [_demo(1, frames), _demo(2, frames)]
    save_dataset(tmp_path / "d.npz", demos, {"scenario": "task: cotter_pin"})
    loaded, metadata = load_dataset(tmp_path / "d.npz")
    assert metadata["format_version"] == 3
    for demo in loaded:
        np.testing.assert_array_equal(demo.frame_A, frames[0])
        np.testing.assert_array_equal(demo.frame_b, frames[1])
    # A format 2 dataset: no frames, loads with frame_A None.
    arrays = dict(np.load(tmp_path / "d.npz"))
    record = json.loads(str(arrays.pop("metadata")))
    record["format_version"] = 2
    old = {k: v for k, v in arrays.items() if "frame_" not in k}
    np.savez(tmp_path / "old.npz", metadata=np.array(json.dumps(record)), **old)
    loaded, _ = load_dataset(tmp_path / "old.npz")
    assert all(demo.frames is None for demo in loaded)
    np.testing.assert_array_equal(loaded[1].p_WE, demos[1].p_WE)
    with pytest.raises(ValueError, match="frames for every demonstration or for none"):
        save_dataset(tmp_path / "e.npz", [_demo(1, frames), _demo(2)])
    with pytest.raises(ValueError, match="'frame_A', 'frame_b' must have shapes"):
        _demo(1, (np.eye(3), np.zeros(3)))


def test_moved_demonstration_is_the_rigid_motion_between_scene_frames():
    demo = _demo(3)
    yaw = np.radians(25)
    R = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    source, target = (np.eye(3), np.array([0.6, -0.8, 0.1])), (R, np.array([0.5, -0.7, 0.2]))
    moved = moved_demonstration(demo, source, target)
    # Independently: the point's coordinates in the source frame, placed in the target frame.
    p_T = demo.p_WE - source[1]
    np.testing.assert_allclose(moved.p_WE, p_T @ R.T + target[1], atol=1e-12)
    np.testing.assert_allclose(moved.f_WE, demo.f_WE @ R.T, atol=1e-12)
    np.testing.assert_array_equal(moved.gain, demo.gain)
    assert moved_demonstration(demo, source, source) is demo


def test_reproduce_at_a_new_placement_end_to_end(tmp_path):
    """Demonstrations at three placements -> TP-HSMM -> reproduce with the scene moved and
    turned: the start and the comparison are the demonstrations carried there."""
    run = tmp_path / "run"
    both = "learning.task_frames=base_and_scene"  # the robot's base and the scene
    demonstrate(pin(*RANGES, "duration=2.0", both), run, replays=False, progress=quiet)
    demos, _ = load_dataset(run / "dataset.npz")
    assert len({float(d.frame_b[1, 0]) for d in demos}) == 3
    model = learn(run, progress=quiet)
    assert isinstance(model, TaskParameterisedHSMM) and model.n_frames_ == 2
    assert isinstance(load_model(run / "model.npz"), TaskParameterisedHSMM)
    new = [0.655, -0.845, 0.12]
    overrides = [f"scene.position=[{new[0]},{new[1]},{new[2]}]", "scene.yaw_deg=12"]
    metrics = reproduce(run, overrides=overrides, replay=False, progress=quiet)
    assert metrics["scene_position"] == new and metrics["scene_yaw_deg"] == 12
    np.testing.assert_allclose(metrics["start"], new, atol=0.004)  # the ring, moved
    log = np.load(run / "reproduction.npz")
    np.testing.assert_allclose(log["x_star"][0], metrics["start"], atol=1e-9)
    assert metrics["position_rmse_m"] < 0.01
    assert metrics["pull_direction_error_deg"] < 10 and metrics["grasp_position_error_m"] < 0.005
    # The LQR tracker takes the placed model unchanged too.
    lqr = ["reproduction.tracker=lqr", "reproduction.restoring_gain=0"]
    other = reproduce(run, overrides=[*overrides, *lqr], out_dir=tmp_path / "lqr", replay=False,
                      progress=quiet)  # fmt: skip
    assert other["tracker"] == "lqr" and other["position_rmse_m"] < 0.01
    np.testing.assert_allclose(other["start"], metrics["start"], atol=1e-12)


def test_placements_figure_draws_demonstrations_grey_and_the_reproduction_red():
    from types import SimpleNamespace

    from hemg_drake.viz.figures import plot_placements

    scenario = pin("scene.yaw_deg=30")
    frames = task_frames(scenario)
    demos = [_demo(1, frames), _demo(2, frames)]
    log = SimpleNamespace(time=demos[0].time, p_WE=demos[0].p_WE + 0.1, f_WE=demos[0].f_WE)
    figure = plot_placements(demos, log, task="cotter_pin", X_WT=scenario.X_WT())
    lines = figure.axes[0].get_lines()
    colours = [line.get_color() for line in lines]
    assert colours.count("tab:red") == 3  # path, start, frame origin
    assert sum(c in ("0.6", "0.45") for c in colours) == 6  # two paths, starts, frames
    labels = [t.get_text() for t in figure.axes[0].get_legend().get_texts()]
    assert labels == ["demonstrations", "reproduction at a new placement"]


def test_cli_reproduces_at_a_new_placement(tmp_path, capsys):
    from hemg_drake.cli import main

    run = tmp_path / "run"
    demonstrate(pin(*RANGES), run, replays=False, progress=quiet)
    assert main(["learn", str(run)]) == 0
    assert main([
        "reproduce", str(run), "--no-replay", "--out", str(tmp_path / "new"),
        "--set", "scene.position=[0.66,-0.85,0.12]", "--set", "scene.yaw_deg=-15",
    ]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "TP-HSMM (task frames: scene)" in out
    metrics = json.loads((tmp_path / "new" / "metrics.json").read_text())
    assert metrics["scene_position"] == [0.66, -0.85, 0.12] and metrics["scene_yaw_deg"] == -15
    np.testing.assert_allclose(metrics["start"], [0.66, -0.85, 0.12], atol=0.004)


def test_run_demo_with_placements_reproduces_each_task_at_a_new_placement(tmp_path):
    from hemg_drake.demo import PLACEMENT_DEMOS, run_demo

    results = run_demo(tmp_path, tasks=["cotter_pin"],
                       overrides=["num_demonstrations=2", "duration=1.0"],
                       replays=False, placements=True, progress=quiet)  # fmt: skip
    assert set(results) == {
        "cotter_pin", "cotter_pin (start 3 cm away)", "cotter_pin (new placement)"
    }  # fmt: skip
    new = results["cotter_pin (new placement)"]
    position, yaw = PLACEMENT_DEMOS["cotter_pin"][1]
    assert new["scene_position"] == position and new["scene_yaw_deg"] == yaw
    folder = tmp_path / "cotter_pin" / "placements"
    assert (folder / "placements.png").is_file()
    assert isinstance(load_model(folder / "model.npz"), TaskParameterisedHSMM)
    assert json.loads((tmp_path / "metrics.json").read_text())["cotter_pin (new placement)"] == new
