"""The whole chain in one diagram: activation step -> sEMG -> RMS envelope -> gain."""

import numpy as np
import pytest

from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.chain import add_emg_gain_chain
from hemg_drake.emg.envelope import RmsEnvelope
from hemg_drake.emg.gain import activation, gain_from_activation
from hemg_drake.emg.sources import SyntheticEmgSource, synthesize_emg

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
