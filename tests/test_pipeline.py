"""The pipeline at small scale: demonstrate, learn, reproduce the cotter pin; errors leave files."""

import json
import shutil

import numpy as np
import pytest

from hemg_drake.cli import main
from hemg_drake.learning.demos import load_dataset, save_dataset
from hemg_drake.learning.hsmm import HSMM
from hemg_drake.pipeline import learn, reproduce, run_demo

# The paper's four demonstrations, at most 20 EM iterations, no HTML replays.
SMALL = dict(changes={}, n_iter=20, replays=False)


@pytest.fixture(scope="module")
def pin_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    results = run_demo(out, tasks=["cotter_pin"], progress=lambda line: None, **SMALL)
    return out, results


def test_demo_writes_every_file_and_the_metrics(pin_run):
    out, results = pin_run
    run = out / "cotter_pin"
    for name in (
        "dataset.npz", "demonstrations.png", "fig6_emg.png", "model.npz",
        "state_activations.png", "reproduction.npz", "fig8_reproduction.png", "metrics.json",
        "demonstration_diagram.svg", "reproduction_diagram.svg",
        "start_offset/metrics.json", "start_offset/fig8_reproduction.png",
    ):  # fmt: skip
        assert (run / name).is_file(), name
    assert "<svg" in (run / "reproduction_diagram.svg").read_text()
    saved = json.loads((out / "metrics.json").read_text())
    assert saved == json.loads(json.dumps(results))
    assert set(saved) == {"cotter_pin", "cotter_pin (start 3 cm away)"}


def test_pin_is_pulled_out_within_table_ii(pin_run):
    _, results = pin_run
    metrics = results["cotter_pin"]
    assert metrics["success"] and metrics["pin_displacement_m"] > 0.05
    assert metrics["position_rmse_m"] <= 0.0022
    assert metrics["velocity_rmse_m_per_s"] <= 0.0788
    assert metrics["stiffness_correlation"] > 0.5
    assert metrics["tracking_force_peak_n"] >= metrics["tracking_force_mean_n"] > 0
    # From x*_0 3 cm aside of the pull axis (the arm held at rest against the grasp), the pin
    # comes out too, and the reproduction returns to the demonstrated path: within Table II.
    offset = results["cotter_pin (start 3 cm away)"]
    assert offset["success"] and offset["restoring_gain"] > 0
    assert np.allclose(offset["start_offset"], [0.03, 0.0, 0.0])
    assert offset["position_rmse_m"] <= 0.0022
    assert offset["velocity_rmse_m_per_s"] <= 0.0788


def test_same_seeds_same_metrics(pin_run, tmp_path):
    out, results = pin_run
    shutil.copy(out / "cotter_pin" / "dataset.npz", tmp_path / "dataset.npz")
    learn(tmp_path, n_iter=SMALL["n_iter"], progress=lambda line: None)
    again = reproduce(tmp_path, replay=False, progress=lambda line: None)
    assert again == results["cotter_pin"]


def test_reproduce_command_from_an_offset_start(pin_run, tmp_path, capsys):
    out, _ = pin_run
    command = ["reproduce", str(out / "cotter_pin"), "--start-offset", "0", "0", "-0.03"]
    assert main([*command, "--out", str(tmp_path), "--no-replay"]) == 0
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["start_offset"] == [0.0, 0.0, -0.03] and metrics["success"]
    assert metrics["restoring_gain"] == 2.0  # the pipeline's default
    assert "pos RMSE (mm)" in capsys.readouterr().out
    assert not (tmp_path / "reproduction.html").exists()
    # A bad restoring gain is a one-line error, before anything is written.
    assert main([*command, "--out", str(tmp_path / "bad"), "--restoring-gain", "-1"]) == 2
    assert "restoring_gain must be finite, >= 0" in capsys.readouterr().err
    assert not (tmp_path / "bad" / "metrics.json").exists()


def test_missing_run_folder_is_a_clear_error(tmp_path, capsys):
    with pytest.raises(FileNotFoundError, match="run folder not found"):
        learn(tmp_path / "nowhere")
    assert main(["reproduce", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("hemg-drake reproduce: error: run folder not found")
    assert len(err.splitlines()) == 1


def test_too_few_demonstrations_leaves_the_model(pin_run, tmp_path, capsys):
    out, _ = pin_run
    demos, metadata = load_dataset(out / "cotter_pin" / "dataset.npz")
    save_dataset(tmp_path / "dataset.npz", demos[:1], metadata)
    shutil.copy(out / "cotter_pin" / "model.npz", tmp_path / "model.npz")
    before = (tmp_path / "model.npz").read_bytes()
    assert main(["learn", str(tmp_path)]) == 2
    assert "too few demonstrations for N = 4 states" in capsys.readouterr().err
    assert (tmp_path / "model.npz").read_bytes() == before
    assert not (tmp_path / "state_activations.png").exists()


def test_model_of_another_dimension_leaves_the_metrics(pin_run, tmp_path):
    out, _ = pin_run
    for name in ("dataset.npz", "metrics.json"):
        shutil.copy(out / "cotter_pin" / name, tmp_path / name)
    planar = [np.random.default_rng(0).normal(size=(50, 4))]
    HSMM(2, n_iter=2, n_position=2).fit(planar).save(tmp_path / "model.npz")
    before = (tmp_path / "metrics.json").read_bytes()
    with pytest.raises(ValueError, match=r"model.npz: the model has D = 4"):
        reproduce(tmp_path, replay=False, progress=lambda line: None)
    assert (tmp_path / "metrics.json").read_bytes() == before
    assert not (tmp_path / "reproduction.npz").exists()


@pytest.fixture(scope="module")
def drawing_run(tmp_path_factory):
    """Learn and reproduce drawing from three demonstrations synthesised from the seeded plans.

    The operator's seeded plans are followed exactly (no teleoperation simulated, to keep the
    test small): the master's position is the plan's, mapped back to the master, and so is
    the tool point; stiffness 150 with the pen on the paper, 40 in the air, a 2 N contact
    force while the plan presses the pen below the sheet. The reproduction runs in the scene.
    """
    from hemg_drake.diagrams.demonstration import workspace_mapping
    from hemg_drake.learning.demos import Demonstration
    from hemg_drake.pipeline import SCENARIOS_DIR
    from hemg_drake.scenario import load_scenario
    from hemg_drake.tasks.drawing import DrawingParams

    run = tmp_path_factory.mktemp("drawing")
    scenario = load_scenario(SCENARIOS_DIR / "drawing.yaml")
    operator = scenario.operator
    paper = DrawingParams().paper_center[2]
    demos = []
    for seed in scenario.seeds():
        plan = scenario.task_plan().perturbed(
            seed,
            timing_std=operator.timing_std,
            path_std=operator.path_std,
            effort_std=operator.effort_std,
        )
        t = np.arange(0.0, scenario.duration + 1e-9, scenario.log_period)
        p_WE = plan.position(t)
        down = p_WE[:, 2] < paper
        zeros = np.zeros(len(t))
        demos.append(Demonstration(
            seed=seed, time=t, p_WE=p_WE, v_WE=plan.velocity(t),
            p_MS=workspace_mapping(scenario).slave_to_master(p_WE),
            envelope=zeros, activation=zeros, gain=np.where(down, 150.0, 40.0),
            f_WE=np.outer(2.0 * down, [0.0, 0.0, 1.0]),
        ))  # fmt: skip
    save_dataset(run / "dataset.npz", demos, {"scenario": scenario.to_yaml()})
    learn(run, n_iter=20, progress=lambda line: None)
    quiet = dict(replay=False, progress=lambda line: None)
    offset = reproduce(run, start_offset=(0.0, 0.03, 0.0), out_dir=run / "offset", **quiet)
    return reproduce(run, **quiet), offset


def test_drawing_three_strokes_stiff_on_paper(drawing_run):
    for metrics in drawing_run:
        assert metrics["success"] and metrics["strokes"] == 3
        assert metrics["stiffness_on_paper"] > metrics["stiffness_in_air"] + 50.0
        assert metrics["stiffness_correlation"] > 0.7
    # The line is drawn in shape; from 3 cm aside the reproduction returns to the demonstrated
    # path (the cross-track attractor, time constant 0.5 s) before the first stroke: every
    # stroke lands within 3 mm of where it lands from the demonstrations' start.
    metrics, offset = drawing_run
    assert offset["restoring_gain"] > 0
    assert metrics["stroke_shape_error_m"][0] <= 0.005
    for placed, aside in zip(
        metrics["stroke_placement_error_m"], offset["stroke_placement_error_m"], strict=True
    ):
        assert aside <= placed + 0.003


def test_drawing_every_stroke_shape_within_5_mm(drawing_run):
    # From both starts, every stroke's shape against the demonstrations' mean stroke.
    for metrics in drawing_run:
        assert max(metrics["stroke_shape_error_m"]) <= 0.005
