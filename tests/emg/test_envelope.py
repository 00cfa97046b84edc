"""RMS envelope (eqs. 1-2): the offline function by hand, the system against it."""

import numpy as np
import pytest

from hemg_drake.emg.envelope import RmsEnvelope, moving_rms
from hemg_drake.emg.sources import FileEmgSource, synthesize_emg
from hemg_drake.fileio import save_npz_atomic


def test_moving_rms_by_hand():
    # Channel sums 1, 2, -3 (eq. 1); window 2, zero before the start (eq. 2).
    samples = np.zeros((3, 8))
    samples[:, 0] = [1, 4, -1]
    samples[:, 5] = [0, -2, -2]
    expected = np.sqrt([1 / 2, (1 + 4) / 2, (4 + 9) / 2])
    np.testing.assert_allclose(moving_rms(samples, 2), expected, rtol=1e-15)
    # Per channel: channel 0 -> sqrt([1/2, 17/2, 17/2]), channel 5 -> sqrt([0, 4/2, 8/2]).
    per_channel = np.sqrt([1 / 2, 17 / 2, 17 / 2]) + np.sqrt([0, 2, 4])
    np.testing.assert_allclose(moving_rms(samples, 2, per_channel=True), per_channel, rtol=1e-15)


def test_moving_rms_of_constant_signal_is_its_magnitude():
    samples = np.tile([3, -1, 2, 0, 0, 1, -2, 4], (50, 1))  # channel sum 7
    rms = moving_rms(samples, 20)
    np.testing.assert_allclose(rms[19:], 7.0, rtol=1e-15)
    np.testing.assert_allclose(rms[:19], 7.0 * np.sqrt(np.arange(1, 20) / 20), rtol=1e-15)
    np.testing.assert_allclose(moving_rms(samples, 20, per_channel=True)[19:], 13.0, rtol=1e-15)


def _run_rms(builder, simulate, tmp_path, samples, **kwargs):
    path = tmp_path / "rec.npz"
    save_npz_atomic(path, emg=samples)
    source = builder.AddSystem(FileEmgSource(filename=path))
    rms = builder.AddSystem(RmsEnvelope(**kwargs))
    builder.Connect(source.get_emg_output_port(), rms.get_emg_input_port())
    return simulate(builder, {"rms": rms.get_envelope_output_port()}, len(samples))["rms"][:, 0]


def brute_force_rms(samples, window, per_channel):
    """Eqs. 1-2 one window at a time: zeros before the start, divided by L_win."""
    rms = np.empty(len(samples))
    for k in range(len(samples)):
        rows = [samples[j] if j >= 0 else np.zeros(8) for j in range(k - window + 1, k + 1)]
        if per_channel:
            rms[k] = sum(
                np.sqrt(sum(row[i] ** 2 for row in rows) / window) for i in range(8)
            )
        else:
            rms[k] = np.sqrt(sum(sum(row) ** 2 for row in rows) / window)
    return rms


@pytest.mark.parametrize("window", [1, 7, 20])
@pytest.mark.parametrize("per_channel", [False, True])
def test_system_equals_a_brute_force_rms(builder, simulate, tmp_path, window, per_channel):
    # 150 samples wrap the ring of 7 and of 20 several times.
    rng = np.random.default_rng(window)
    samples = rng.integers(-128, 128, size=(150, 8))
    samples[60:90] //= 8  # a quieter stretch, so the window has something to follow
    rms = _run_rms(builder, simulate, tmp_path, samples, window=window, per_channel=per_channel)
    np.testing.assert_allclose(rms, brute_force_rms(samples, window, per_channel), rtol=1e-13)


@pytest.mark.parametrize("window", [1, 7, 20])
@pytest.mark.parametrize("per_channel", [False, True])
def test_system_equals_offline_exactly(builder, simulate, tmp_path, window, per_channel):
    activation = np.concatenate([np.full(60, 0.1), np.full(90, 0.9)])
    samples = synthesize_emg(activation, seed=8)
    rms = _run_rms(builder, simulate, tmp_path, samples, window=window, per_channel=per_channel)
    np.testing.assert_array_equal(rms, moving_rms(samples, window, per_channel=per_channel))


def test_system_on_non_integer_input_does_not_drift(builder, simulate, held_signal):
    # 3000 samples of large, non-integer values: the running sum is recomputed
    # at every wrap of the ring, so the error stays at rounding level.
    samples = np.random.default_rng(4).normal(0.0, 1e3, size=(3000, 8)) + 0.123
    source = builder.AddSystem(held_signal(samples))
    rms = builder.AddSystem(RmsEnvelope(window=20))
    builder.Connect(source.get_output_port(), rms.get_emg_input_port())
    out = simulate(builder, {"rms": rms.get_envelope_output_port()}, len(samples))["rms"][:, 0]
    np.testing.assert_allclose(out, moving_rms(samples, 20), rtol=1e-12)


def test_system_recovers_from_nan_within_two_windows(builder, simulate, held_signal):
    samples = np.ones((100, 8))
    samples[30] = np.nan
    source = builder.AddSystem(held_signal(samples))
    rms = builder.AddSystem(RmsEnvelope(window=10))
    builder.Connect(source.get_output_port(), rms.get_emg_input_port())
    out = simulate(builder, {"rms": rms.get_envelope_output_port()}, 100)["rms"][:, 0]
    assert np.isnan(out[30])
    np.testing.assert_array_equal(out[30 + 2 * 10 :], 8.0)


@pytest.mark.parametrize("window", [0, -3, 2.5, True])
def test_bad_window(window):
    with pytest.raises(ValueError, match="window"):
        moving_rms(np.zeros((5, 8)), window)
    with pytest.raises(ValueError, match="window"):
        RmsEnvelope(window=window)


def test_bad_samples():
    with pytest.raises(ValueError, match="shape"):
        moving_rms(np.zeros(10), 3)
    with pytest.raises(ValueError, match="shape"):
        moving_rms(np.zeros((0, 8)), 3)
    with pytest.raises(ValueError, match="NaN"):
        moving_rms(np.full((4, 8), np.nan), 3)
    with pytest.raises(ValueError, match="period"):
        RmsEnvelope(period=-1.0)


def test_a_sixteen_channel_armband_in_volts_through_the_envelope():
    """The envelope takes the source's channel count: 16 channels of volts, both forms."""
    import numpy as np
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from hemg_drake.emg.envelope import RmsEnvelope

    sample = np.linspace(-1e-4, 2e-4, 16)  # volts
    for per_channel, expected in ((False, abs(sample.sum())), (True, None)):
        builder = DiagramBuilder()
        source = builder.AddSystem(ConstantVectorSource(sample))
        rms = builder.AddSystem(RmsEnvelope(window=5, per_channel=per_channel, channels=16))
        builder.Connect(source.get_output_port(), rms.get_emg_input_port())
        simulator = Simulator(builder.Build())
        simulator.AdvanceTo(0.1)  # 20 samples: the window is full of the constant sample
        context = rms.GetMyContextFromRoot(simulator.get_context())
        envelope = rms.get_envelope_output_port().Eval(context)[0]
        if per_channel:  # each channel's RMS is |x_c|, summed over the channels
            expected = float(np.sum(np.abs(sample)))
        assert envelope == pytest.approx(expected, rel=1e-12)
    with pytest.raises(ValueError, match="channels must be a positive integer"):
        RmsEnvelope(channels=0)
