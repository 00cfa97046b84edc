"""The example sEMG recording shipped with the package: MYO layout, two contractions."""

from importlib import resources

import numpy as np

from hemg_drake.emg.sources import load_emg_recording

EXAMPLE = resources.files("hemg_drake") / "data" / "example_emg.csv"


def test_example_recording_reads_as_five_seconds_of_myo_samples():
    emg = load_emg_recording(EXAMPLE)
    assert emg.shape == (1000, 8)  # 5 s at 200 Hz, 8 channels
    assert emg.min() >= -128 and emg.max() <= 127
    # The file itself: 8 integers per line, no header.
    first = EXAMPLE.read_text(encoding="ascii").splitlines()[0].split(",")
    assert len(first) == 8 and all(field.lstrip("-").isdigit() for field in first)


def test_example_recording_holds_two_contractions_between_rests():
    emg = load_emg_recording(EXAMPLE).astype(float)
    # RMS of the channel sum over 0.25 s blocks, computed here by hand.
    summed = emg.sum(axis=1).reshape(20, 50)
    rms = np.sqrt((summed**2).mean(axis=1))
    rest = rms[[0, 9, 19]]  # 0-0.25 s, 2.25-2.5 s, 4.75-5 s
    contraction = rms[[5, 14]]  # 1.25-1.5 s, 3.5-3.75 s
    assert contraction.min() > 4 * rest.max()
    above = rms > (rest.max() + contraction.min()) / 2
    # Exactly two separate runs of high activity.
    assert np.count_nonzero(np.diff(above.astype(int)) == 1) == 2
