"""`hemg-drake emg-figure`: Fig. 6 from a recording or the synthetic source; every mistake
refused in one line before anything is computed."""

import numpy as np
import pytest

from hemg_drake.cli import MAX_EMG_FIGURE_DURATION, main
from hemg_drake.emg.sources import save_emg_recording, synthesize_emg
from hemg_drake.fileio import write_text_atomic

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def no_figure(monkeypatch):
    """Drawing the figure fails the test: a refused input must be refused before it."""
    import hemg_drake.viz.figures as figures

    def drawn(*args, **kwargs):
        pytest.fail("plot_emg_envelopes was called")

    monkeypatch.setattr(figures, "plot_emg_envelopes", drawn)


@pytest.fixture
def no_synthesis(monkeypatch, no_figure):
    """Neither the synthetic recording nor the figure may be made (an unbounded duration
    would allocate gigabytes)."""
    import hemg_drake.emg.sources as sources

    def synthesized(*args, **kwargs):
        pytest.fail("synthesize_emg was called")

    monkeypatch.setattr(sources, "synthesize_emg", synthesized)


@pytest.fixture
def short_recording(tmp_path):
    """A 1.5 s (300-sample) MYO recording as CSV."""
    path = tmp_path / "rec.csv"
    save_emg_recording(path, synthesize_emg(np.full(300, 0.5), seed=1))
    return path


def test_synthetic_figure(tmp_path, run_cli):
    out = tmp_path / "fig6.png"
    argv = ["emg-figure", "--duration", "2", "--windows", "10", "20", "-o", str(out)]
    code, stdout, _ = run_cli(argv)
    assert code == 0
    assert out.read_bytes()[:8] == PNG
    assert str(out) in stdout


def test_figure_from_csv_recording(tmp_path, short_recording):
    out = tmp_path / "fig.png"
    assert main(["emg-figure", str(short_recording), "--per-channel", "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == PNG
    # A window as long as the recording is allowed.
    assert main(["emg-figure", str(short_recording), "--windows", "300", "-o", str(out)]) == 0


def test_bad_recording_is_a_one_line_error(tmp_path, run_cli):
    recording = tmp_path / "bad.csv"
    write_text_atomic(recording, "1,2,3\n")
    out = tmp_path / "fig.png"
    code, _, err = run_cli(["emg-figure", str(recording), "-o", str(out)])
    assert code == 2
    assert err.count("\n") == 1 and "bad.csv: line 1: expected 8" in err
    assert not out.exists()


def test_window_longer_than_the_recording_is_refused(tmp_path, run_cli, short_recording, no_figure):
    out = tmp_path / "fig.png"
    code, _, err = run_cli(
        ["emg-figure", str(short_recording), "--windows", "20", "5000", "-o", str(out)]
    )
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("hemg-drake emg-figure: error: --windows [5000] longer than")
    assert "300 samples" in err
    assert not out.exists()


def test_window_longer_than_the_synthetic_recording_is_refused(tmp_path, run_cli, no_figure):
    # 0.1 s at 200 Hz: 20 samples, so L_win = 30 does not fit.
    code, _, err = run_cli(["emg-figure", "--duration", "0.1", "--windows", "30",
                            "-o", str(tmp_path / "f.png")])  # fmt: skip
    assert code == 2 and err.count("\n") == 1 and "--windows [30] longer than" in err


@pytest.mark.parametrize("kind", ["folder", "under a file"])
def test_unwritable_output_is_one_line_before_any_work(tmp_path, run_cli, no_synthesis, kind):
    file = tmp_path / "file"
    file.write_text("x")
    target = tmp_path if kind == "folder" else file / "fig6.png"
    code, _, err = run_cli(["emg-figure", "-o", str(target)])
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    expected = (
        f"{tmp_path}: is a folder" if kind == "folder" else f"{file}: exists and is not a folder"
    )
    assert expected in err
    assert file.read_text() == "x"


@pytest.mark.parametrize(
    "options, message",
    [
        (["--duration", "inf"], "--duration must be a positive number and at most 600, got inf"),
        (["--duration", "nan"], "--duration must be a positive number and at most 600, got nan"),
        (["--duration", "1e6"], "--duration must be a positive number and at most 600, got 1e6"),
        (["--duration", "0"], "--duration must be a positive number and at most 600, got 0"),
        (["--duration", "ten"], "--duration must be a number, got 'ten'"),
        (["--windows", "20", "0"], "--windows must be at least 1, got 0"),
        (["--seed", "-1"], "--seed must not be negative, got -1"),
    ],
)
def test_bad_option_is_one_line(tmp_path, run_cli, no_synthesis, options, message):
    out = tmp_path / "f.png"
    code, stdout, err = run_cli(["emg-figure", *options, "-o", str(out)])
    assert code == 2 and stdout == "" and "Traceback" not in err
    assert err == f"hemg-drake emg-figure: error: argument {options[0]}: {message}\n"
    assert not out.exists()


def test_duration_bound_is_ten_minutes():
    assert MAX_EMG_FIGURE_DURATION == 600.0


def test_duration_below_one_sample_is_refused(tmp_path, run_cli, no_synthesis):
    code, _, err = run_cli(["emg-figure", "--duration", "0.001", "-o", str(tmp_path / "f.png")])
    assert code == 2 and err.count("\n") == 1
    assert "--duration must be at least one sample (5 ms), got 0.001" in err
