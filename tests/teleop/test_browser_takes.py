"""The browser master's takes end to end: the CLI that appends them and learn that takes them,
interrupted and refused takes, the drawn stroke and per-seed placements (the real page:
test_teleop_page.py)."""

import dataclasses as dc
import hashlib
import math
import socket

import numpy as np
import pytest

from hemg_drake.cli import main
from hemg_drake.learning.demos import load_dataset
from hemg_drake.run_folder import RunFolder
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.teleop.browser_inputs import SLIDER_ACTIVATION, SLIDER_X, load_inputs
from hemg_drake.teleop_session import run_take, teleop


def _first_line(capsys):
    return capsys.readouterr().out.splitlines()


def test_cli_appends_takes_that_learn_accepts_and_replays_them(tmp_path, capsys):
    out = tmp_path / "run"
    args = ["teleop", "cotter_pin", "--out", str(out), "--port", "0", "--no-replay", "--no-wait"]
    assert main([*args, "--duration", "0.3"]) == 0
    lines = _first_line(capsys)
    assert lines[0].startswith("Teleop page: http://localhost:")
    assert int(lines[0].split()[2].rsplit(":", 1)[1].strip("/")) > 0
    assert main([*args, "--duration", "0.2", "--takes", "2"]) == 0  # two on one page
    lines = _first_line(capsys)
    assert lines[0].startswith("Teleop page: ") and sum(x.startswith("Teleop page") for x in lines) == 1
    log = load_inputs(out / "inputs_1.npz")
    assert len(log.time) == 30  # 100 Hz
    # Re-driven headless from take 1's log: a third take equal to the first, bit for bit.
    assert main(["teleop", "cotter_pin", "--out", str(out), "--no-replay",
                 "--replay-inputs", str(out / "inputs_1.npz")]) == 0  # fmt: skip
    demos, metadata = load_dataset(out / "dataset.npz")
    assert len(demos) == 4 and metadata["operators"][:3] == ["browser"] * 3
    assert metadata["seeds"] == [1, 2, 3, 1]  # scenario.seed + c - 1; the replay: the log's
    assert [len(d) for d in demos] == [31, 21, 21, 31]  # the log period, both ends
    for field in dc.fields(demos[0]):
        assert np.array_equal(getattr(demos[0], field.name), getattr(demos[3], field.name))
    folder = RunFolder(out)
    folder.check("demonstrate", folder.dataset, run_hint="x")
    for name in ("inputs_1.npz", "inputs_2.npz", "inputs_3.npz", "inputs_4.npz"):
        folder.check("demonstrate", out / name, run_hint="x")


def _hash(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_interrupted_take_writes_nothing_and_keeps_the_old_takes(scenario, visualization, tmp_path):
    teleop(scenario, tmp_path, visualization=visualization, duration=0.2, replays=False, realtime=False,
           progress=lambda line: None)  # fmt: skip
    before = _hash(tmp_path / "dataset.npz")

    def interrupt(t):
        if t > 0.1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        teleop(scenario, tmp_path, visualization=visualization, duration=5.0, replays=True, realtime=False,
               on_step=interrupt, progress=lambda line: None)  # fmt: skip
    assert _hash(tmp_path / "dataset.npz") == before
    assert not (tmp_path / "inputs_2.npz").exists() and not (tmp_path / "replay_2.html").exists()
    assert not list(tmp_path.glob(".*.tmp"))


def test_port_in_use_and_other_scenario_are_one_line_errors(tmp_path, capsys):
    with socket.socket() as taken:
        taken.bind(("localhost", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        code = main(["teleop", "cotter_pin", "--out", str(tmp_path), "--port", str(port)])
    err = capsys.readouterr().err
    assert code == 2 and "in use" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "dataset.npz").exists()
    assert main(["teleop", "cotter_pin", "--out", str(tmp_path), "--port", "0", "--no-replay",
                 "--no-wait", "--duration", "0.05"]) == 0  # fmt: skip
    capsys.readouterr()
    code = main(["teleop", "drawing", "--out", str(tmp_path), "--port", "0"])
    err = capsys.readouterr().err
    assert code == 2 and "another scenario" in err


def test_a_take_joins_simulated_demonstrations_and_learn_takes_them(tmp_path, capsys):
    out = str(tmp_path / "run")
    short = ["--set", "duration=0.4"]
    assert main(["demonstrate", "cotter_pin", "--out", out, "--demos", "1", "--no-replay",
                 *short]) == 0  # fmt: skip
    # The shipped scenario as it is: only the length and count differ, which takes ignore.
    assert main(["teleop", "cotter_pin", "--out", out, "--port", "0", "--duration", "0.3",
                 "--no-replay", "--no-wait"]) == 0  # fmt: skip
    demos, metadata = load_dataset(tmp_path / "run" / "dataset.npz")
    assert metadata["operators"] == ["simulated", "browser"]
    assert (demos[0].frame_A is None) == (demos[1].frame_A is None)
    assert main(["learn", out, "--set", "learning.num_states=2"]) == 0
    assert "wrote" in capsys.readouterr().out


def test_a_keyboard_take_draws_the_first_stroke_on_the_sheet(meshcat, visualization):
    """A person's key taps (TAP_MM per tap, scripted through the page's sliders) steer the
    stylus along the drawing's first stroke at a third of the plan's speed (held keys are
    slower than the plan): the pen touches the sheet and draws the line."""
    from hemg_drake.evaluation import strokes
    from hemg_drake.tasks.metrics import stroke_errors
    from hemg_drake.teleop.browser_inputs import SLIDER_Y, SLIDER_Z, TAP_MM

    slow = 3.0
    scenario = load_scenario(shipped_scenario("drawing"), overrides=[f"duration={2.9 * slow}"])
    plan, mapping = scenario.task_plan(), scenario.workspace_mapping()
    end = 2.8  # the first stroke is drawn and the pen lifted by then (plan time)

    def script(t):
        t = t / slow
        target_mm = 1e3 * mapping.slave_to_master(plan.position(min(t + 0.1, end)))
        pressing = plan.segment(min(t, end)).pen_down
        for name, value in zip((SLIDER_X, SLIDER_Y, SLIDER_Z), target_mm):
            # While drawing, the person keeps the pen pressed: the vertical key (SLIDER_Y,
            # W/S) rounds down, into the sheet; the others to the nearest tap.
            steps = math.floor(value / TAP_MM) if name == SLIDER_Y and pressing else round(
                value / TAP_MM
            )
            meshcat.SetSliderValue(name, TAP_MM * steps)
        meshcat.SetSliderValue(SLIDER_ACTIVATION, 0.8 if pressing else 0.2)

    take = run_take(scenario, seed=5, visualization=visualization, duration=2.9 * slow,
                    realtime=False, on_step=script, progress=lambda line: None)  # fmt: skip
    demo = take.demonstration
    drawn = strokes(demo.time, demo.p_WE, demo.f_WE)
    assert len(drawn) == 1
    # The plan's line, seen from above, against the ink: the same 11 cm line within 5 mm.
    first, second = [i for i, down in enumerate(plan.pen_down) if down][:2]
    line = plan.points[[first + 1, second + 1], :2]  # pressed at the line's start, its end
    length = np.linalg.norm(drawn[0][-1, :2] - drawn[0][0, :2])
    assert length == pytest.approx(np.linalg.norm(line[-1] - line[0]), abs=0.015)
    assert stroke_errors(drawn[0][:, :2], [line])["shape"] < 0.005


def test_takes_with_placements_happen_each_at_its_own_seeds_placement(visualization, tmp_path):
    from hemg_drake.learning.demos import load_dataset
    from hemg_drake.placements import demonstration_scenario, task_frames

    placed = load_scenario(shipped_scenario("cotter_pin"), overrides=[
        "scene.placements.position_range=[[0.62,-0.86,0.11],[0.67,-0.81,0.13]]",
        "scene.placements.yaw_range_deg=[-20,20]",
    ])  # fmt: skip
    lines = []
    for _ in range(2):
        teleop(placed, tmp_path, visualization=visualization, duration=0.1, replays=False, realtime=False,
               progress=lines.append)  # fmt: skip
    demos, _ = load_dataset(tmp_path / "dataset.npz")
    origins = []
    for c, demo in enumerate(demos):
        # Take c has seed scenario.seed + c: its frames are that seed's drawn placement, and
        # the arm starts at that placement's ring (the grasp), not at the shipped one.
        A, b = task_frames(demonstration_scenario(placed, placed.seed + c))
        np.testing.assert_array_equal(demo.frame_A, A)
        np.testing.assert_array_equal(demo.frame_b, b)
        np.testing.assert_allclose(demo.p_WE[0], b[1], atol=0.005)
        origins.append(b[1])
        here = demonstration_scenario(placed, placed.seed + c)
        yaw = here.scene.yaw_deg
        said = f"take {c + 1}: scene at {np.round(b[1], 3).tolist()} m, yaw {yaw:.1f}"
        assert any(line.startswith(said) for line in lines), lines
    assert np.linalg.norm(origins[0] - origins[1]) > 0.003  # two placements, not one
