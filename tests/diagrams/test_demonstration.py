"""The teleoperated demonstration loop, simulated through Drake at small scale."""

import base64
import re
from pathlib import Path

import numpy as np
import pytest
from pydrake.geometry import Meshcat, MeshcatParams, MeshcatVisualizer
from pydrake.systems.analysis import Simulator

from hemg_drake.diagrams.demonstration import (
    build_demonstration_diagram,
    demonstration_from_log,
    run_demonstration,
    workspace_mapping,
)
from hemg_drake.scenario import load_scenario, parse_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"

# Free space: from the tool's home point, 10 cm up-forward-left, then down-back-right.
FREE_SPACE = """
task: cotter_pin
duration: 2.6
plan:
  times: [0.3, 1.3, 2.3]
  points: [[0.64, -0.84, 0.12], [0.70, -0.78, 0.18], [0.61, -0.89, 0.09]]
  kinds: [free, forceful]
"""


def distance_to_path(points, path):
    """Distance of each point, shape (n, 3), to the polyline ``path``, shape (m, 3)."""
    a, b = path[:-1], path[1:]
    ab = b - a
    t = np.einsum("nmk,mk->nm", points[:, None] - a, ab) / np.maximum((ab**2).sum(1), 1e-300)
    closest = a + np.clip(t, 0.0, 1.0)[..., None] * ab
    return np.linalg.norm(points[:, None] - closest, axis=2).min(axis=1)


def simulate(scenario, seed, **kwargs):
    built = build_demonstration_diagram(scenario, seed=seed, **kwargs)
    simulator = Simulator(built.diagram)
    simulator.AdvanceTo(scenario.duration)
    root = simulator.get_context()
    demo = demonstration_from_log(built.logger.FindLog(root), seed)
    return built, demo, built.plant.GetMyContextFromRoot(root)


@pytest.fixture(scope="module")
def free_space():
    scenario = parse_scenario(FREE_SPACE)
    return scenario, simulate(scenario, 3, scene=False)[1]


def test_free_space_slave_follows_the_mapped_master(free_space):
    scenario, demo = free_space
    assert len(demo) == 261 and demo.time[-1] == pytest.approx(2.6)
    p_WE_desired = workspace_mapping(scenario).master_to_slave(demo.p_MS)
    travel = np.ptp(p_WE_desired, axis=0)
    assert np.linalg.norm(travel) > 0.1  # the operator really moved the master
    # Reached: 5.0 mm at the same instant (the slave lags during the fastest motion, about
    # 0.3 m/s), 2.4 mm RMS; 4.1 mm from the path itself, lag aside; 0.1 mm once at rest.
    error = np.linalg.norm(demo.p_WE - p_WE_desired, axis=1)
    assert error.max() < 0.006 and np.sqrt(np.mean(error**2)) < 0.003
    assert distance_to_path(demo.p_WE, p_WE_desired).max() < 0.005
    assert error[demo.time > 2.4].max() < 0.0005
    # v_WE agrees with the logged positions' central differences (an independent check).
    dt = np.diff(demo.time)[0]
    v_numeric = (demo.p_WE[2:] - demo.p_WE[:-2]) / (2 * dt)
    assert np.abs(v_numeric - demo.v_WE[1:-1]).max() < 0.02
    assert np.abs(demo.v_WE).max() > 0.1
    # Free space: nothing pushes on the tool.
    assert not np.any(demo.f_WE)


def test_gain_follows_the_operators_effort(free_space):
    scenario, demo = free_space
    plan = scenario.task_plan()
    assert demo.gain.min() >= scenario.emg.k_min and demo.gain.max() <= scenario.emg.k_max
    free = (demo.time > 0.3) & (demo.time < 1.3)
    forceful = (demo.time > 1.5) & (demo.time < 2.3)
    assert plan.kinds == ("free", "forceful")
    assert demo.gain[forceful].mean() > 1.5 * demo.gain[free].mean()
    assert demo.activation[forceful].mean() > demo.activation[free].mean()
    # The envelope and the gain rise and fall together (eq. 22 is monotone).
    assert np.corrcoef(demo.envelope, demo.gain)[0, 1] > 0.8


def test_same_seed_same_demonstration_bitwise():
    scenario = parse_scenario(FREE_SPACE.replace("duration: 2.6", "duration: 0.8"))
    first = run_demonstration(scenario, 11, scene=False)
    again = run_demonstration(scenario, 11, scene=False)
    other = run_demonstration(scenario, 12, scene=False)
    for name in ("time", "p_WE", "v_WE", "p_MS", "envelope", "activation", "gain", "f_WE"):
        assert getattr(first, name).tobytes() == getattr(again, name).tobytes(), name
    assert not np.array_equal(first.envelope, other.envelope)
    assert not np.array_equal(first.p_MS, other.p_MS)


def test_diagram_structure_and_bad_input():
    scenario = parse_scenario(FREE_SPACE)
    built = build_demonstration_diagram(scenario, seed=0, scene=False)
    for name in (
        "plant", "scene_graph", "operator", "master", "workspace_map", "clik", "pd",
        "emg_source", "envelope", "variable_gain", "gain_hold", "force_feedback",
        "tool_point", "logger",
    ):
        assert built.diagram.HasSubsystemNamed(name), name
    assert built.scene is None
    assert not np.array_equal(built.plan.points, scenario.task_plan().points)
    assert not any(isinstance(s, MeshcatVisualizer) for s in built.diagram.GetSystems())
    live = build_demonstration_diagram(
        scenario, seed=0, scene=False, meshcat=Meshcat(MeshcatParams(host="localhost", port=0))
    )
    assert any(isinstance(s, MeshcatVisualizer) for s in live.diagram.GetSystems())
    with pytest.raises(ValueError, match="seed"):
        build_demonstration_diagram(scenario, seed=-1, scene=False)
    far = parse_scenario(FREE_SPACE.replace("[0.64, -0.84, 0.12]", "[2.5, 0.0, 0.0]"))
    with pytest.raises(ValueError, match="out of the arm's reach"):
        build_demonstration_diagram(far, seed=0, scene=False)


def test_calibration_shorter_than_the_window_is_refused():
    # 0.05 s of the MYO's 200 Hz is 10 samples, fewer than L_win = 20: no envelope to calibrate.
    with pytest.raises(ValueError, match="emg.calibration_duration' gives 10 samples.*window.*20"):
        parse_scenario(FREE_SPACE + "emg: {calibration_duration: 0.05}\n")


PIN = "task: cotter_pin\nduration: 3.0\nmapping: {offset: [0.642, -0.837, 0.17]}\nfeedback: {gain: 0.2}\n"


def test_cotter_pin_comes_out_with_the_emg_gain():
    scenario = parse_scenario(PIN)
    built, demo, plant_context = simulate(scenario, 1)
    assert built.scene.pin_out(plant_context)
    # The operator tensed up to pull: the gain peaks high, and the pin resisted (felt force).
    assert demo.gain.max() > 100
    assert demo.f_WE[:, 2].min() < -20


def test_cotter_pin_stays_in_with_a_constant_low_gain():
    # k_max barely above k_min: the gain is 10 whatever the muscles do.
    scenario = parse_scenario(PIN + "emg: {k_min: 10.0, k_max: 10.01}\n")
    built, demo, plant_context = simulate(scenario, 1)
    assert np.ptp(demo.gain) <= 0.01
    assert not built.scene.pin_out(plant_context)
    assert built.scene.pin_displacement(plant_context) < 0.005
    # The operator did ask for the pull: the master went up by the plan's travel.
    assert np.ptp(workspace_mapping(scenario).master_to_slave(demo.p_MS)[:, 2]) > 0.04


def test_position_error_feedback_pulls_the_stylus_back_to_a_held_slave():
    # The paper's master PD (Table I: K_pm = K_dm = 50) in the whole diagram: the pin holds
    # the slave (K = 10), so the stylus that the operator pushed up is pulled back down.
    scenario = parse_scenario(
        "task: cotter_pin\nduration: 2.0\nmapping: {offset: [0.642, -0.837, 0.17]}\n"
        "feedback: {mode: position_error}\nemg: {k_min: 10.0, k_max: 10.01}\n"
    )
    built = build_demonstration_diagram(scenario, seed=1)
    simulator = Simulator(built.diagram)
    simulator.AdvanceTo(scenario.duration)
    root = simulator.get_context()
    assert not built.scene.pin_out(built.plant.GetMyContextFromRoot(root))
    diagram = built.diagram
    feedback = diagram.GetSubsystemByName("force_feedback")
    tool = diagram.GetSubsystemByName("tool_point")
    master = diagram.GetSubsystemByName("master")

    def port(system, name):
        return system.GetOutputPort(name).Eval(system.GetMyContextFromRoot(root))

    mapping = workspace_mapping(scenario)
    gap = mapping.slave_to_master(port(tool, "p_WE")) - port(master, "p_MS")
    gap_rate = mapping.velocity_to_master(port(tool, "v_WE")) - port(master, "v_MS")
    expected = 50.0 * gap + 50.0 * gap_rate
    assert gap[1] < -0.005  # the stylus is more than 5 mm above where the slave is held
    motor_force = port(feedback, "motor_force")
    limit = scenario.feedback.peak_force
    np.testing.assert_allclose(
        motor_force, expected * min(1.0, limit / np.linalg.norm(expected)), rtol=1e-9
    )
    assert motor_force[1] < -1.0  # downwards (+y_M is up), towards the held slave


def test_drawing_inks_three_strokes_with_high_stiffness_on_the_paper():
    from hemg_drake.tasks.drawing import drawing_steps
    from hemg_drake.viz.ink import in_contact, ink_strokes

    scenario = load_scenario(SCENARIOS / "drawing.yaml")
    built = build_demonstration_diagram(scenario, seed=scenario.seed)
    scenario = scenario.replaced(duration=built.plan.end_time)
    built, demo, _ = simulate(scenario, scenario.seed)
    plan = built.plan  # what this seeded operator meant to draw
    touching = in_contact(demo.f_WE)
    strokes = ink_strokes(demo.time, demo.p_WE, touching)
    assert len(strokes) == 3
    down = np.flatnonzero(np.diff(np.concatenate([[0], np.array(plan.pen_down, int), [0]])))
    for ink, first, stop in zip(strokes, down[0::2], down[1::2]):
        planned = plan.points[first : stop + 1, :2]  # the stroke's corners on the sheet
        assert distance_to_path(ink[:, :2], planned).max() < 0.005
        # ... and the ink covers the whole stroke: every corner is within 5 mm of the ink.
        assert distance_to_path(planned, ink[:, :2]).max() < 0.005
    steps = drawing_steps(plan)
    lifts = [(demo.time > steps[i]) & (demo.time < steps[i + 1]) for i in (1, 3)]
    drawn = [demo.gain[touching & (demo.time > steps[i]) & (demo.time < steps[i + 1])]
             for i in (0, 2, 4)]
    low = max(demo.gain[lift].mean() for lift in lifts)
    high = min(gain.mean() for gain in drawn)
    assert high > 1.5 * low


def _replay_payload(path):
    """The binary Meshcat messages embedded (base64) in an HTML replay."""
    html = Path(path).read_text()
    return b"".join(base64.b64decode(chunk) for chunk in re.findall(r"base64,([A-Za-z0-9+/=]+)", html))


def test_drawing_replay_shows_the_ink(tmp_path):
    from hemg_drake.viz.ink import in_contact

    # The first stroke starts at about 1.4 s: 1.8 s leave a short line of ink.
    scenario = load_scenario(SCENARIOS / "drawing.yaml").replaced(duration=1.8)
    demo = run_demonstration(scenario, scenario.seed, replay_path=tmp_path / "replay.html")
    assert in_contact(demo.f_WE).sum() > 10
    payload = _replay_payload(tmp_path / "replay.html")
    assert b"/ink/stroke_0/piece_0" in payload and b"/ink/stroke_1" not in payload


def test_demonstrate_command_end_to_end(tmp_path, capsys):
    from hemg_drake.cli import main
    from hemg_drake.learning.demos import load_dataset

    out = tmp_path / "run"
    argv = ["demonstrate", str(SCENARIOS / "cotter_pin.yaml"), "--out", str(out)]
    assert main([*argv, "--demos", "2", "--duration", "0.5"]) == 0
    printed = capsys.readouterr().out
    assert "demonstration 2/2 (seed 2)" in printed and "wrote" in printed
    # 0.5 s is less than the operator's plan: each line says the run was cut short.
    assert printed.count("cut short: the operator's plan ends at 3.") == 2
    names = ["dataset.npz", "demonstrations.png", "replay_1.html", "replay_2.html"]
    assert sorted(p.name for p in out.iterdir()) == names
    demos, metadata = load_dataset(out / "dataset.npz")
    assert [d.seed for d in demos] == [1, 2] and len(demos[0]) == 51
    again = parse_scenario(metadata["scenario"])
    assert (again.task, again.num_demonstrations, again.duration) == ("cotter_pin", 2, 0.5)
    assert metadata["num_states"] == 4
    assert (out / "demonstrations.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<html" in (out / "replay_1.html").read_bytes()[:1000].lower()

    # A second run replaces its files whole (no temporaries left; replay_2.html of the first
    # run stays: nothing is deleted), and the same seed gives the same data.
    assert main([*argv, "--demos", "1", "--duration", "0.5"]) == 0
    assert sorted(p.name for p in out.iterdir()) == names
    demos_again, _ = load_dataset(out / "dataset.npz")
    assert len(demos_again) == 1 and demos_again[0].p_WE.tobytes() == demos[0].p_WE.tobytes()

    assert main([*argv, "--demos", "0"]) == 2
    assert "num_demonstrations" in capsys.readouterr().err
    assert main(["demonstrate", str(tmp_path / "none.yaml"), "--out", str(out)]) == 2
    assert "not found" in capsys.readouterr().err


def test_plot_demonstrations_layouts(free_space):
    from hemg_drake.viz.figures import plot_demonstrations

    _, demo = free_space
    pin = plot_demonstrations([demo, demo], task="cotter_pin")
    assert len(pin.axes) == 6 and all(len(axes.lines) == 2 for axes in pin.axes)
    np.testing.assert_array_equal(pin.axes[5].lines[0].get_ydata(), demo.v_WE[:, 2])
    drawing = plot_demonstrations([demo], task="drawing")
    assert [axes.get_ylabel() for axes in drawing.axes][-1] == "stiffness K"
    np.testing.assert_array_equal(drawing.axes[3].lines[0].get_ydata(), demo.gain)
    with pytest.raises(ValueError, match="task"):
        plot_demonstrations([demo], task="welding")
    with pytest.raises(ValueError, match="at least one"):
        plot_demonstrations([], task="drawing")
