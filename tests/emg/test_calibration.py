"""Rest / MVC calibration: levels from recordings, normalisation, YAML files."""

import numpy as np
import pytest

from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.envelope import moving_rms
from hemg_drake.emg.config import SyntheticEmgConfig
from hemg_drake.emg.sources import synthesize_emg
from hemg_drake.fileio import write_text_atomic


@pytest.fixture(scope="module")
def calibration():
    rest = synthesize_emg(np.zeros(2000), seed=1)
    mvc = synthesize_emg(np.ones(2000), seed=2)
    return EmgCalibration.from_recordings(rest, mvc, window=20)


def test_levels_match_the_source_model(calibration):
    # The channel sum of independent zero-mean channels has std sqrt(sum std_i^2)
    # (plus 1/12 per channel from rounding); the mean RMS over 20 samples sits
    # just below it.
    config = SyntheticEmgConfig()
    gains = np.asarray(config.channel_gains)
    rest_std = np.sqrt(8 * (config.rest_std**2 + 1 / 12))
    mvc_std = np.sqrt(np.sum((config.rest_std + gains) ** 2 + 1 / 12))
    assert calibration.rest_level == pytest.approx(rest_std, rel=0.05)
    assert calibration.mvc_level == pytest.approx(mvc_std, rel=0.05)


def test_normalised_envelope_is_near_identity_and_monotone(calibration):
    # What the simulated operator relies on: activation in, about the same out.
    levels = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)
    means = []
    for k, a in enumerate(levels):
        envelope = moving_rms(synthesize_emg(np.full(1500, a), seed=10 + k), 20)
        means.append(calibration.normalise(envelope[19:]).mean())
    assert np.all(np.diff(means) > 0)
    np.testing.assert_allclose(means[1:-1], levels[1:-1], atol=0.05)
    # At the ends the clip to [0, 1] pulls the mean of a noisy envelope inwards.
    assert means[0] < 0.05 and means[-1] > 0.9


def test_normalise_by_hand():
    calibration = EmgCalibration(rest_level=10.0, mvc_level=50.0)
    np.testing.assert_allclose(
        calibration.normalise([0.0, 10.0, 20.0, 50.0, 80.0]), [0.0, 0.0, 0.25, 1.0, 1.0]
    )
    assert np.isnan(calibration.normalise(np.nan))


def test_yaml_round_trip(tmp_path, calibration):
    path = tmp_path / "calibration.yaml"
    calibration.save(path)
    assert EmgCalibration.load(path) == calibration


@pytest.mark.parametrize(
    "text, message",
    [
        ("rest_level: 5.0\nmvc_level: 2.0\n", "rest_level < mvc_level"),
        ("rest_level: 1.0\nmvc_level: 2.0\nwindow: 0\n", "window"),
        ("rest_level: 1.0\nmvc_level: 2.0\ngain: 3\n", "gain"),
        ("rest_level: [1, 2]\n", "rest_level"),
    ],
)
def test_malformed_yaml_names_file_and_problem(tmp_path, text, message):
    path = tmp_path / "bad.yaml"
    write_text_atomic(path, text)
    with pytest.raises(ValueError, match=message) as error:
        EmgCalibration.load(path)
    assert "bad.yaml" in str(error.value)


def test_missing_file_and_bad_levels(tmp_path):
    with pytest.raises(FileNotFoundError, match="none.yaml"):
        EmgCalibration.load(tmp_path / "none.yaml")
    with pytest.raises(ValueError, match="rest_level < mvc_level"):
        EmgCalibration(rest_level=3.0, mvc_level=3.0)
    with pytest.raises(ValueError, match="rest_level < mvc_level"):
        EmgCalibration(rest_level=np.nan, mvc_level=3.0)
    with pytest.raises(ValueError, match="at least window=20"):
        EmgCalibration.from_recordings(np.zeros((5, 8)), np.ones((50, 8)), window=20)
