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
    assert set(saved) == {"cotter_pin", "cotter_pin (start +3 cm)"}


def test_pin_is_pulled_out_within_table_ii(pin_run):
    _, results = pin_run
    metrics = results["cotter_pin"]
    assert metrics["success"] and metrics["pin_displacement_m"] > 0.05
    assert metrics["position_rmse_m"] <= 0.0022
    assert metrics["velocity_rmse_m_per_s"] <= 0.0788
    assert metrics["stiffness_correlation"] > 0.5
    assert metrics["tracking_force_peak_n"] >= metrics["tracking_force_mean_n"] > 0
    # From 3 cm beside the demonstrations' start, the pin comes out too.
    offset = results["cotter_pin (start +3 cm)"]
    assert offset["success"]
    assert np.allclose(offset["start_offset"], [0.0, 0.03, 0.0])


def test_same_seeds_same_metrics(pin_run, tmp_path):
    out, results = pin_run
    shutil.copy(out / "cotter_pin" / "dataset.npz", tmp_path / "dataset.npz")
    learn(tmp_path, n_iter=SMALL["n_iter"], progress=lambda line: None)
    again = reproduce(tmp_path, replay=False, progress=lambda line: None)
    assert again == results["cotter_pin"]


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
