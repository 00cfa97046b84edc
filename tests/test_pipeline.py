"""The pipeline at small scale: demonstrate -> learn -> reproduce on run folders, provenance
that refuses mixed runs, learning from the logged reference, Fig. 6 from the logged sEMG,
and a moved scene end to end."""

import json
import shutil

import numpy as np
import pytest

from hemg_drake.cli import main
from hemg_drake.learning.demos import load_dataset, save_dataset
from hemg_drake.learning.hsmm import HSMM
from hemg_drake.demo import run_demo
from hemg_drake.pipeline import demonstrate, learn, learning_data, reproduce
from hemg_drake.run_folder import RunFolder, file_hash
from hemg_drake.scenario import load_scenario, shipped_scenario

# Two demonstrations of 1 s (and two fresh ones to score against) and five EM iterations:
# every stage runs, in seconds.
SMALL = ["num_demonstrations=2", "duration=1.0", "learning.n_iter=5", "reproduction.num_heldout=2"]


def quiet(line):
    pass


def small(task, *overrides):
    return load_scenario(shipped_scenario(task), overrides=[*SMALL, *overrides])


@pytest.fixture(scope="module")
def pin_run(tmp_path_factory):
    """``run_demo`` for the cotter pin at small scale; the figures it saved, by file name."""
    import hemg_drake.viz.figures as figures

    out = tmp_path_factory.mktemp("runs")
    saved = {}
    save_figure = figures.save_figure

    def keep(figure, path, **kwargs):
        # The training run's, not the fresh demonstrations' (heldout/, built beside it).
        if not any("heldout" in part for part in path.parts):
            saved[path.name] = figure
        save_figure(figure, path, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(figures, "save_figure", keep)
        results = run_demo(
            out, tasks=["cotter_pin"], overrides=SMALL, replays=False, progress=quiet
        )
    return out, results, saved


def copy_run(pin_run, tmp_path):
    """A copy of the pin's run folder to change (the module's run stays as it was)."""
    out, _, _ = pin_run
    run = tmp_path / "run"
    shutil.copytree(out / "cotter_pin", run)
    return run


def test_demo_writes_every_stage_and_the_metrics(pin_run):
    out, results, _ = pin_run
    run = out / "cotter_pin"
    for name in (
        "dataset.npz", "demonstrations.png", "fig6_emg.png", "model.npz",
        "state_activations.png", "reproduction.npz", "fig8_reproduction.png", "metrics.json",
        "manifest.json", "start_offset/metrics.json", "start_offset/fig8_reproduction.png",
        "start_offset/manifest.json", "heldout/dataset.npz", "heldout/manifest.json",
    ):  # fmt: skip
        assert (run / name).is_file(), name
    # No replays asked for: none written.
    assert not list(run.rglob("*.html"))
    # The diagrams, as SVG with Graphviz or as .dot text without it.
    for name in ("demonstration_diagram", "reproduction_diagram"):
        assert (run / f"{name}.svg").is_file() or (run / f"{name}.dot").is_file()
    saved = json.loads((out / "metrics.json").read_text())
    assert saved == json.loads(json.dumps(results))
    assert set(saved) == {"cotter_pin", "cotter_pin (start 3 cm away)"}
    assert json.loads((run / "metrics.json").read_text()) == saved["cotter_pin"]
    # The small-scale settings reached every stage.
    demos, metadata = load_dataset(run / "dataset.npz")
    assert len(demos) == 2 and metadata["seeds"] == [1, 2]
    # Every reproduction scored out of sample against the fresh demonstrations first.
    fresh, _ = load_dataset(run / "heldout" / "dataset.npz")
    assert [demo.seed for demo in fresh] == [9001, 9002]
    for name in saved:
        assert list(saved[name])[:2] == ["scores", "out_of_sample"]
        assert saved[name]["out_of_sample"]["seeds"] == [9001, 9002]
        assert saved[name]["out_of_sample"]["training_seeds"] == [1, 2]
    assert all(abs(demo.time[-1] - 1.0) < 1e-9 for demo in demos)
    model = HSMM.load(run / "model.npz")
    assert model.n_states == 4 and model.n_iter_ <= 5
    offset = results["cotter_pin (start 3 cm away)"]
    np.testing.assert_allclose(offset["start_offset"], [0.03, 0.0, 0.0])
    np.testing.assert_allclose(
        np.subtract(offset["start"], results["cotter_pin"]["start"]), [0.03, 0.0, 0.0], atol=1e-12
    )


def test_manifest_chains_each_stage_to_what_it_was_made_from(pin_run):
    run = pin_run[0] / "cotter_pin"
    entries = json.loads((run / "manifest.json").read_text())
    dataset, model = file_hash(run / "dataset.npz"), file_hash(run / "model.npz")
    assert entries["demonstrate"]["files"]["dataset.npz"] == dataset
    assert entries["learn"]["inputs"] == {"dataset.npz": dataset}
    assert entries["learn"]["files"]["model.npz"] == model
    fresh = file_hash(run / "heldout" / "dataset.npz")
    assert entries["reproduce"]["inputs"] == {
        "dataset.npz": dataset, "model.npz": model, "heldout/dataset.npz": fresh
    }
    assert entries["reproduce"]["files"]["metrics.json"] == file_hash(run / "metrics.json")


def test_fig6_is_drawn_from_the_logged_raw_semg(pin_run):
    out, _, saved = pin_run
    demos, _ = load_dataset(out / "cotter_pin" / "dataset.npz")
    demo = demos[0]
    raw_axes, envelope_axes = saved["fig6_emg.png"].axes
    (raw_line,) = raw_axes.get_lines()
    np.testing.assert_array_equal(raw_line.get_ydata(), demo.emg.sum(axis=1))
    np.testing.assert_allclose(raw_line.get_xdata(), np.arange(len(demo.emg)) / 200.0)
    lines = {line.get_label(): line for line in envelope_axes.get_lines()}
    assert set(lines) == {"L_win = 10", "L_win = 20", "L_win = 30"}
    plotted = np.asarray(lines["L_win = 20"].get_ydata())
    assert len(plotted) == len(demo.emg) == 200
    # The envelope the gain chain read, logged every 10 ms, is the plotted L_win = 20
    # envelope at the sEMG sample the chain held then (sample 2m - 1 at log sample m),
    # sample for sample and exactly.
    m = np.arange(1, len(demo.time))
    np.testing.assert_array_equal(demo.envelope[m], plotted[2 * m - 1])
    # Both are eq. 2 on the summed channels (eq. 1), written here: RMS over 20 samples, the
    # ones before the first taken as zeros.
    u = demo.emg.sum(axis=1)
    padded = np.concatenate([np.zeros(19), u])
    rms = np.sqrt([np.mean(padded[k : k + 20] ** 2) for k in range(len(u))])
    np.testing.assert_allclose(plotted, rms, rtol=1e-12, atol=1e-9)
    # The recording is the raw MYO signal: int8 values, not a re-synthesised one.
    assert np.all(demo.emg == np.round(demo.emg)) and np.abs(demo.emg).max() <= 128
    assert demo.emg.std() > 1.0


def test_learn_refuses_a_dataset_no_demonstrate_recorded(pin_run, tmp_path, capsys):
    out, _, _ = pin_run
    shutil.copy(out / "cotter_pin" / "dataset.npz", tmp_path / "dataset.npz")
    with pytest.raises(ValueError) as error:
        learn(tmp_path, progress=quiet)
    message = str(error.value)
    assert "\n" not in message and "no finished 'demonstrate' recorded it" in message
    assert message.endswith("run hemg-drake demonstrate SCENARIO --out NEW_FOLDER for a new run")
    assert not (tmp_path / "model.npz").exists()
    assert main(["learn", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("hemg-drake learn: error:") and err.count("\n") == 1


def test_too_many_states_leave_the_old_model(pin_run, tmp_path):
    run = copy_run(pin_run, tmp_path)
    before = (run / "model.npz").read_bytes()
    with pytest.raises(ValueError, match="too few demonstrations for N = 40 states"):
        learn(run, overrides=["learning.num_states=40"], progress=quiet)
    # Checked before anything was written: the model and what was made from it stay.
    assert (run / "model.npz").read_bytes() == before
    assert (run / "metrics.json").is_file()
    entries = json.loads((run / "manifest.json").read_text())
    assert entries == json.loads((pin_run[0] / "cotter_pin" / "manifest.json").read_text())


def test_demonstrating_another_task_into_the_folder_refuses_the_old_model(pin_run, tmp_path):
    # Issue 14: a drawing demonstrated into a folder holding a cotter-pin run.
    run = copy_run(pin_run, tmp_path)
    pin_model = tmp_path / "pin_model.npz"
    shutil.copy(run / "model.npz", pin_model)
    lines = []
    demonstrate(small("drawing"), run, replays=False, progress=lines.append)
    assert any("of the older run" in line for line in lines)
    # Everything made from the pin's dataset is gone with it.
    for name in ("model.npz", "state_activations.png", "metrics.json", "reproduction.npz",
                 "fig8_reproduction.png", "start_offset/metrics.json"):  # fmt: skip
        assert not (run / name).exists(), name
    assert json.loads((run / "manifest.json").read_text()).keys() == {"demonstrate"}
    _, metadata = load_dataset(run / "dataset.npz")
    assert metadata["task"] == "drawing"

    def refused():
        with pytest.raises((ValueError, FileNotFoundError)) as error:
            reproduce(run, replay=False, progress=quiet)
        message = str(error.value)
        assert "\n" not in message and message.endswith(f"run hemg-drake learn {run}")
        assert not (run / "metrics.json").exists()

    refused()
    # The pin's model put back by hand is refused too: it was not fitted on this dataset.
    shutil.copy(pin_model, run / "model.npz")
    refused()


def test_a_model_fitted_on_an_older_dataset_is_refused(pin_run, tmp_path, capsys):
    # The folder's manifest records a learn stage, but of another dataset than the one now
    # in the folder (demonstrate's record replaced by hand, as a copy between folders would).
    run = copy_run(pin_run, tmp_path)
    folder = RunFolder(run)
    demos, metadata = load_dataset(run / "dataset.npz")
    save_dataset(run / "dataset.npz", demos[:1] * 2, metadata)
    entries = folder.manifest()
    folder.finish("demonstrate", [run / "dataset.npz"])
    assert folder.manifest()["learn"] == entries["learn"]
    assert main(["reproduce", str(run), "--no-replay"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "model.npz: was not made from this folder's dataset.npz" in err
    assert err.endswith(f"run hemg-drake learn {run}\n")


def test_reproduce_without_replay_leaves_no_old_replay(pin_run, tmp_path, capsys):
    run = copy_run(pin_run, tmp_path)
    # A replay of an earlier reproduction, beside the metrics.
    folder = RunFolder(run)
    earlier = [run / name for name in folder.manifest()["reproduce"]["files"]]
    (run / "reproduction.html").write_text("<html>an earlier reproduction</html>\n")
    earlier.append(run / "reproduction.html")
    folder.finish("reproduce", earlier, inputs=[folder.model, folder.dataset])
    old_metrics = (run / "metrics.json").read_bytes()
    assert main(["reproduce", str(run), "--no-replay", "--weighting", "forward"]) == 0
    assert not (run / "reproduction.html").exists()
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["weighting"] == "forward" and (run / "metrics.json").read_bytes() != old_metrics
    assert "pos RMSE out / in / floor (mm)" in capsys.readouterr().out
    entries = json.loads((run / "manifest.json").read_text())
    assert "reproduction.html" not in entries["reproduce"]["files"]


def test_reproduce_into_another_folder_from_an_offset(pin_run, tmp_path):
    out, results, _ = pin_run
    command = ["reproduce", str(out / "cotter_pin"), "--start-offset", "0", "0", "0.02"]
    assert main([*command, "--out", str(tmp_path), "--no-replay"]) == 0
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["start_offset"] == [0.0, 0.0, 0.02]
    assert metrics["restoring_gain"] == 2.0  # the shipped scenario's
    np.testing.assert_allclose(
        np.subtract(metrics["start"], results["cotter_pin"]["start"]), [0, 0, 0.02], atol=1e-12
    )
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert {str((tmp_path / name).resolve()) for name in manifest["reproduce"]["inputs"]} == {
        str((out / "cotter_pin" / name).resolve()) for name in ("model.npz", "dataset.npz")
    }
    # The run folder itself is untouched.
    assert json.loads((out / "cotter_pin" / "metrics.json").read_text()) == results["cotter_pin"]


def test_interrupted_demonstrate_leaves_no_partial_output(tmp_path, monkeypatch):
    import hemg_drake.pipeline as pipeline

    calls = []

    def record(built, seed, *, replay_path=None, **kwargs):
        calls.append(seed)
        if len(calls) == 2:
            raise KeyboardInterrupt
        replay_path.write_text("<html>demonstration 1</html>\n")  # the first replay, done

    monkeypatch.setattr(pipeline, "demonstrate_seed", record)
    run = tmp_path / "run"
    run.mkdir()
    (run / "manifest.json").write_text("{}\n")  # a run folder (with a person's notes)
    (run / "notes.txt").write_text("mine\n")
    with pytest.raises(KeyboardInterrupt):
        demonstrate(small("cotter_pin"), run, replays=True, progress=quiet)
    assert calls == [1, 2]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # nothing left beside it
    assert {p.name: p.read_text() for p in run.iterdir()} == {
        "manifest.json": "{}\n", "notes.txt": "mine\n"
    }  # fmt: skip


def test_learning_data_is_the_logged_reference_delayed_and_paired_with_the_gain(tmp_path):
    # 30 master samples (1 ms each) of transport delay: 3 log periods of 10 ms.
    n = 30
    scenario = small("cotter_pin", "num_demonstrations=1", f"mapping.delay_steps={n}",
                     "learning.positions=reference")  # fmt: skip
    demonstrate(scenario, tmp_path, replays=False, progress=quiet)
    (demo,), _ = load_dataset(tmp_path / "dataset.npz")
    (data,) = learning_data([demo], scenario)
    assert data.shape == (len(demo.time), 7)
    # The learnt reference, at log sample m, is the mapped master position of 30 ms
    # before; the stiffness beside it is the gain logged at sample m.
    mapping = scenario.workspace_mapping()
    mapped = mapping.p_WMo + mapping.scale * demo.p_MS @ mapping.R_WM.matrix().T
    shift = n // 10
    np.testing.assert_allclose(data[shift:, :3], mapped[:-shift], rtol=0, atol=1e-9)
    np.testing.assert_allclose(data[:shift, :3], np.tile(mapped[0], (shift, 1)), atol=1e-9)
    np.testing.assert_array_equal(data[:, 6], demo.gain)
    # ... and neither the undelayed map nor another delay: the master moved by centimetres.
    for other in (0, shift - 1, shift + 1):
        error = np.abs(data[other:, :3] - mapped[: len(mapped) - other]).max()
        assert error > 0.005, other
    # The rate is the reference's own, by central differences over the log.
    dt = np.diff(demo.time)
    np.testing.assert_allclose(
        data[1:-1, 3:6], (data[2:, :3] - data[:-2, :3]) / (dt[1:] + dt[:-1])[:, None], atol=1e-9
    )
    # The measured tool point lags its reference: learnt from the tool, the data differ.
    (tool,) = learning_data([demo], scenario.replaced(["learning.positions=tool"]))
    np.testing.assert_array_equal(tool[:, :3], demo.p_WE)
    assert np.abs(tool[:, :3] - data[:, :3]).max() > 0.005


def test_a_moved_scene_is_demonstrated_learnt_and_reproduced(tmp_path, capsys):
    p_WT = [0.65, -0.80, 0.12]
    common = ["--set", "learning.n_iter=5"]
    moved = ["--set", f"scene.position=[{p_WT[0]},{p_WT[1]},{p_WT[2]}]"]
    assert main(["demonstrate", "cotter_pin", "--out", str(tmp_path), "--demos", "2",
                 "--duration", "1", "--no-replay", *moved, *common]) == 0  # fmt: skip
    assert main(["learn", str(tmp_path)]) == 0
    assert main(["reproduce", str(tmp_path), "--no-replay"]) == 0
    capsys.readouterr()
    demos, metadata = load_dataset(tmp_path / "dataset.npz")
    assert "0.65" in metadata["scenario"]
    # The demonstrations start at the moved ring, 3.7 cm from the shipped one ...
    for demo in demos:
        np.testing.assert_allclose(demo.p_WE[0], p_WT, atol=0.003)
        np.testing.assert_allclose(demo.p_WE_desired[0], p_WT, atol=1e-9)
    # ... and the reproduction starts from there, learnt from them.
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    np.testing.assert_allclose(metrics["start"], p_WT, atol=0.003)
    reproduced = np.load(tmp_path / "reproduction.npz")
    p_WE = reproduced["p_WE"]
    np.testing.assert_allclose(p_WE[0], p_WT, atol=0.005)
    assert metrics["position_rmse_m"] < 0.01
