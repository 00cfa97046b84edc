"""`hemg-drake emg-figure`: Fig. 6 from a recording or the synthetic source."""

import numpy as np
import pytest

from hemg_drake.cli import main
from hemg_drake.emg.sources import save_emg_recording, synthesize_emg
from hemg_drake.fileio import write_text_atomic

PNG = b"\x89PNG\r\n\x1a\n"


def test_synthetic_figure(tmp_path, capsys):
    out = tmp_path / "fig6.png"
    assert main(["emg-figure", "--duration", "2", "--windows", "10", "20", "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == PNG
    assert str(out) in capsys.readouterr().out


def test_figure_from_csv_recording(tmp_path):
    recording = tmp_path / "rec.csv"
    save_emg_recording(recording, synthesize_emg(np.full(300, 0.5), seed=1))
    out = tmp_path / "fig.png"
    assert main(["emg-figure", str(recording), "--per-channel", "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == PNG


def test_bad_recording_is_a_one_line_error(tmp_path, capsys):
    recording = tmp_path / "bad.csv"
    write_text_atomic(recording, "1,2,3\n")
    out = tmp_path / "fig.png"
    assert main(["emg-figure", str(recording), "-o", str(out)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "bad.csv: line 1: expected 8" in error
    assert not out.exists()


@pytest.mark.parametrize(
    "options, message",
    [
        (["--duration", "0"], "--duration must be at least one sample"),
        (["--windows", "20", "0"], "window must be a positive integer, got 0"),
        (["--seed", "-1"], "seed must be a non-negative integer, got -1"),
    ],
)
def test_bad_option_is_a_one_line_error(tmp_path, capsys, options, message):
    out = tmp_path / "f.png"
    assert main(["emg-figure", *options, "-o", str(out)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and message in error
    assert not out.exists()
