"""The whole chain in one diagram: activation step -> sEMG -> RMS envelope -> gain."""

import numpy as np
import pytest

from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.chain import add_emg_gain_chain, run_emg_chain
from hemg_drake.emg.envelope import RmsEnvelope, moving_rms
from hemg_drake.emg.gain import activation, gain_from_activation
from hemg_drake.emg.sources import (
    FileEmgSource,
    SyntheticEmgSource,
    save_emg_recording,
    synthesize_emg,
)

WINDOW = 20
K_MIN, K_MAX = 10.0, 100.0
STEP = 200  # sample index of the step, t = 1 s
N = 400


@pytest.fixture(scope="module")
def calibration():
    return EmgCalibration.from_recordings(
        synthesize_emg(np.zeros(1000), seed=100), synthesize_emg(np.ones(1000), seed=101), WINDOW
    )


@pytest.fixture
def chain(builder, simulate, held_signal, calibration):
    step = np.where(np.arange(N) < STEP, 0.1, 0.8)
    signal = builder.AddSystem(held_signal(step))
    source = builder.AddSystem(SyntheticEmgSource(seed=7))
    builder.Connect(signal.get_output_port(), source.get_activation_input_port())
    rms, gain = add_emg_gain_chain(
        builder, source.get_emg_output_port(), calibration=calibration, k_min=K_MIN, k_max=K_MAX
    )
    ports = {
        "envelope": rms.get_envelope_output_port(),
        "activation": gain.get_activation_output_port(),
        "gain": gain.get_gain_output_port(),
    }
    return {name: value[:, 0] for name, value in simulate(builder, ports, N).items()}


def test_envelope_rises_within_a_window_of_the_step(chain):
    envelope = chain["envelope"]
    before = envelope[STEP - 100 : STEP].mean()
    after = envelope[STEP + 2 * WINDOW :].mean()
    assert after > 4 * before
    halfway = STEP + np.argmax(envelope[STEP:] > (before + after) / 2)
    assert halfway - STEP <= WINDOW
    # A full window after the step, only post-step samples remain in it.
    assert envelope[STEP + WINDOW :].min() > (before + after) / 2 - 0.3 * (after - before)


def test_gain_rises_monotonically_up_to_noise_and_stays_bounded(chain):
    gain = chain["gain"]
    assert np.all(np.isfinite(gain)) and gain.min() >= K_MIN and gain.max() <= K_MAX
    blocks = gain.reshape(-1, WINDOW // 2).mean(axis=1)  # 10-sample means
    step_block = STEP // (WINDOW // 2)
    noise = blocks[step_block + 4 :].std()
    assert np.all(np.diff(blocks[step_block - 1 : step_block + 3]) > -noise)
    assert blocks[step_block + 4 :].min() > blocks[:step_block].max()


def test_gain_settles_where_the_calibrated_law_says(chain):
    # The normalised envelope tracks the activation (near identity after
    # calibration), so the settled gains follow eq. 22 at u = 0.1 and 0.8.
    gain = chain["gain"]
    for u, settled in ((0.1, gain[WINDOW:STEP]), (0.8, gain[STEP + WINDOW :])):
        expected = gain_from_activation(activation(u), k_min=K_MIN, k_max=K_MAX)
        assert np.mean(settled) == pytest.approx(expected, rel=0.1)


def test_chain_takes_window_and_form_from_calibration(builder):
    calibration = EmgCalibration(rest_level=1.0, mvc_level=9.0, window=7, per_channel=True)
    source = builder.AddSystem(SyntheticEmgSource(seed=0))
    rms, _ = add_emg_gain_chain(builder, source.get_emg_output_port(), calibration=calibration)
    assert isinstance(rms, RmsEnvelope)
    assert (rms.window, rms.per_channel) == (7, True)
    # And the chain computes that envelope: per-channel RMS over 7 samples.
    profile = np.linspace(0.0, 1.0, 50)
    result = run_emg_chain(
        SyntheticEmgSource(seed=3), len(profile), activation=profile, calibration=calibration
    )
    expected = moving_rms(synthesize_emg(profile, 3), 7, per_channel=True)
    np.testing.assert_allclose(result["envelope"], expected, atol=1e-12)
    assert not np.allclose(expected, moving_rms(synthesize_emg(profile, 3), 20))


def test_run_emg_chain_matches_the_numpy_twins_sample_for_sample(calibration):
    profile = np.concatenate([np.full(60, 0.1), np.linspace(0.1, 0.9, 80), np.full(60, 0.9)])
    result = run_emg_chain(
        SyntheticEmgSource(seed=5), len(profile), activation=profile,
        calibration=calibration, k_min=K_MIN, k_max=K_MAX,
    )
    emg = synthesize_emg(profile, 5)
    np.testing.assert_array_equal(result["emg"], emg)
    envelope = moving_rms(emg, WINDOW)
    np.testing.assert_allclose(result["envelope"], envelope, atol=1e-12)
    a = activation(calibration.normalise(envelope))
    np.testing.assert_allclose(result["activation"], a, atol=1e-12)
    expected = gain_from_activation(a, k_min=K_MIN, k_max=K_MAX)
    np.testing.assert_allclose(result["gain"], expected, atol=1e-9)
    np.testing.assert_allclose(result["time"], np.arange(len(profile)) / 200.0)


def test_run_emg_chain_replays_a_saved_recording_to_the_same_gain(tmp_path, calibration):
    profile = np.linspace(0.0, 1.0, 120)
    synthetic = run_emg_chain(
        SyntheticEmgSource(seed=9), 120, activation=profile, calibration=calibration
    )
    path = tmp_path / "recording.csv"
    save_emg_recording(path, synthetic["emg"])
    replayed = run_emg_chain(FileEmgSource(filename=path), 120, calibration=calibration)
    np.testing.assert_array_equal(replayed["gain"], synthetic["gain"])


@pytest.mark.parametrize(
    "make_source, n_samples, kwargs, message",
    [
        (lambda: SyntheticEmgSource(seed=0), 10, {}, "pass activation="),
        (lambda: SyntheticEmgSource(seed=0), 10, {"activation": np.ones(9)}, "10 numbers"),
        (lambda: SyntheticEmgSource(seed=0), 2, {"activation": [0.1, np.nan]}, "without NaN"),
        (lambda: SyntheticEmgSource(seed=0), 0, {"activation": []}, "positive integer"),
    ],
)
def test_run_emg_chain_bad_input(make_source, n_samples, kwargs, message):
    with pytest.raises(ValueError, match=message):
        run_emg_chain(make_source(), n_samples, **kwargs)


def test_run_emg_chain_rejects_activation_for_a_file_source(tmp_path):
    path = tmp_path / "recording.npz"
    save_emg_recording(path, np.zeros((5, 8), dtype=int))
    with pytest.raises(ValueError, match="no activation input"):
        run_emg_chain(FileEmgSource(filename=path), 5, activation=np.zeros(5))
