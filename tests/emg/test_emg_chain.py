"""The whole chain in one diagram: activation step -> sEMG -> RMS envelope -> gain."""

import numpy as np
import pytest

import math

from pydrake.common import RandomGenerator
from pydrake.systems.analysis import Simulator
from pydrake.systems.primitives import LogVectorOutput

from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.chain import add_emg_gain_chain, run_emg_chain
from hemg_drake.emg.config import MYO_PERIOD, EmgConfig
from hemg_drake.emg.envelope import RmsEnvelope
from hemg_drake.emg.sources import (
    make_file_emg_source,
    make_synthetic_emg_source,
    save_emg_recording,
    synthesize_emg,
)

WINDOW = 20
K_MIN, K_MAX = 10.0, 100.0
CONFIG = EmgConfig(window=WINDOW, k_min=K_MIN, k_max=K_MAX)
A = -0.6981


def gain_by_hand(u):
    """Eq. 22 written out: K = K_min + (K_max - K_min) (exp(A u) - 1) / (exp(A) - 1)."""
    return K_MIN + (K_MAX - K_MIN) * (math.exp(A * u) - 1) / (math.exp(A) - 1)
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
    source = builder.AddSystem(make_synthetic_emg_source())
    builder.Connect(signal.get_output_port(), source.GetInputPort("activation"))
    rms, gain = add_emg_gain_chain(
        builder, source.GetOutputPort("emg"), config=CONFIG, calibration=calibration
    )
    ports = {
        "envelope": rms.get_envelope_output_port(),
        "activation": gain.get_activation_output_port(),
        "gain": gain.get_gain_output_port(),
    }
    return {name: value[:, 0] for name, value in simulate(builder, ports, N, seed=7).items()}


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
        assert np.mean(settled) == pytest.approx(gain_by_hand(u), rel=0.1)


def test_chain_takes_window_and_form_from_its_config(builder):
    config = EmgConfig(window=7, per_channel=True)
    calibration = EmgCalibration(rest_level=1.0, mvc_level=9.0, window=7, per_channel=True)
    source = builder.AddSystem(make_synthetic_emg_source())
    rms, _ = add_emg_gain_chain(
        builder, source.GetOutputPort("emg"), config=config, calibration=calibration
    )
    assert isinstance(rms, RmsEnvelope)
    assert (rms.window, rms.per_channel) == (7, True)
    with pytest.raises(ValueError, match="calibration was measured with window=20"):
        add_emg_gain_chain(builder, source.GetOutputPort("emg"), config=config,
                           calibration=EmgCalibration())  # fmt: skip


def test_run_emg_chain_by_hand(calibration):
    # The envelope of the logged sEMG, by a brute-force RMS; the gain, by eq. 22 written out.
    profile = np.concatenate([np.full(60, 0.1), np.linspace(0.1, 0.9, 80), np.full(60, 0.9)])
    result = run_emg_chain(make_synthetic_emg_source(), len(profile), seed=5,
                           activation=profile, config=CONFIG, calibration=calibration)  # fmt: skip
    np.testing.assert_array_equal(result["emg"], synthesize_emg(profile, 5))
    sums = np.concatenate([np.zeros(WINDOW - 1), result["emg"].sum(axis=1)])
    envelope = [math.sqrt(sum(x * x for x in sums[k : k + WINDOW]) / WINDOW) for k in range(200)]
    np.testing.assert_allclose(result["envelope"], envelope, rtol=1e-13)
    rest, mvc = calibration.rest_level, calibration.mvc_level
    u = [min(max((e - rest) / (mvc - rest), 0.0), 1.0) for e in envelope]
    np.testing.assert_allclose(result["gain"], [gain_by_hand(x) for x in u], rtol=1e-12)
    np.testing.assert_allclose(result["time"], np.arange(len(profile)) / 200.0)


def test_run_emg_chain_replays_a_saved_recording_to_the_same_gain(tmp_path, calibration):
    profile = np.linspace(0.0, 1.0, 120)
    synthetic = run_emg_chain(
        make_synthetic_emg_source(), 120, seed=9, activation=profile, calibration=calibration
    )
    path = tmp_path / "recording.csv"
    save_emg_recording(path, synthetic["emg"])
    replayed = run_emg_chain(
        make_file_emg_source(filename=path), 120, seed=0, calibration=calibration
    )
    np.testing.assert_array_equal(replayed["gain"], synthetic["gain"])


def test_the_chain_clones_and_runs_seeds_from_one_diagram(builder, held_signal, calibration):
    signal = builder.AddSystem(held_signal(np.full(100, 0.6)))
    source = builder.AddSystem(make_synthetic_emg_source())
    builder.Connect(signal.get_output_port(), source.GetInputPort("activation"))
    _, gain = add_emg_gain_chain(builder, source.GetOutputPort("emg"), calibration=calibration)
    logger = LogVectorOutput(gain.get_gain_output_port(), builder, publish_period=MYO_PERIOD)
    logger.set_name("gain_logger")
    diagram = builder.Build()

    def gains(system, seed):
        simulator = Simulator(system)
        system.SetRandomContext(simulator.get_mutable_context(), RandomGenerator(seed))
        simulator.AdvanceTo(0.5)
        sink = system.GetSubsystemByName("gain_logger")
        return sink.FindLog(simulator.get_context()).data().tobytes()

    first = gains(diagram, 1)
    assert gains(diagram.Clone(), 1) == first and gains(diagram, 2) != first


@pytest.mark.parametrize(
    "make_source, n_samples, kwargs, message",
    [
        (make_synthetic_emg_source, 10, {}, "pass activation="),
        (make_synthetic_emg_source, 10, {"activation": np.ones(9)}, "10 numbers"),
        (make_synthetic_emg_source, 2, {"activation": [0.1, np.nan]}, "without NaN"),
        (make_synthetic_emg_source, 0, {"activation": []}, "positive integer"),
    ],
)
def test_run_emg_chain_bad_input(make_source, n_samples, kwargs, message):
    with pytest.raises(ValueError, match=message):
        run_emg_chain(make_source(), n_samples, seed=0, **kwargs)


def test_run_emg_chain_rejects_activation_for_a_file_source(tmp_path):
    path = tmp_path / "recording.npz"
    save_emg_recording(path, np.zeros((5, 8), dtype=int))
    with pytest.raises(ValueError, match="no activation input"):
        run_emg_chain(make_file_emg_source(filename=path), 5, seed=0, activation=np.zeros(5))
