"""RMS envelope (eqs. 1-2): the offline function and the system, each against hand values
or a brute-force RMS written here."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, InitializeAutoDiff
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from hemg_drake.emg.config import EnvelopeConfig
from hemg_drake.emg.envelope import RmsEnvelope, moving_rms
from hemg_drake.emg.recording import make_file_emg_source
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


def _run_rms(builder, simulate, tmp_path, samples, window, per_channel=False):
    path = tmp_path / "rec.npz"
    save_npz_atomic(path, emg=samples)
    source = builder.AddSystem(make_file_emg_source(filename=path))
    rms = builder.AddSystem(RmsEnvelope(config=EnvelopeConfig(window=window, per_channel=per_channel)))
    builder.Connect(source.GetOutputPort("emg"), rms.get_emg_input_port())
    return simulate(builder, {"rms": rms.get_envelope_output_port()}, len(samples))["rms"][:, 0]


def test_system_by_hand(builder, simulate, tmp_path):
    # Channel sums 3, 4, 0, 12, -5 (eq. 1); L_win = 3 (eq. 2), zeros before the start:
    # sqrt(9/3), sqrt(25/3), sqrt(25/3), sqrt(160/3), sqrt(169/3).
    samples = np.zeros((5, 8), dtype=int)
    samples[:, 2] = [1, 4, -2, 12, -1]
    samples[:, 7] = [2, 0, 2, 0, -4]
    rms = _run_rms(builder, simulate, tmp_path, samples, 3)
    np.testing.assert_allclose(rms, np.sqrt([9 / 3, 25 / 3, 25 / 3, 160 / 3, 169 / 3]), rtol=1e-15)


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
    rng = np.random.default_rng(window)
    samples = rng.integers(-128, 128, size=(150, 8))
    samples[60:90] //= 8  # a quieter stretch, so the window has something to follow
    rms = _run_rms(builder, simulate, tmp_path, samples, window, per_channel)
    np.testing.assert_allclose(rms, brute_force_rms(samples, window, per_channel), rtol=1e-13)


@pytest.mark.parametrize("per_channel", [False, True])
def test_offline_equals_a_brute_force_rms(per_channel):
    samples = np.random.default_rng(2).integers(-128, 128, size=(90, 8))
    for window in (1, 7, 20):
        np.testing.assert_allclose(
            moving_rms(samples, window, per_channel=per_channel),
            brute_force_rms(samples, window, per_channel),
            rtol=1e-13,
        )


def test_system_on_non_integer_input(builder, simulate, held_signal):
    samples = np.random.default_rng(4).normal(0.0, 1e3, size=(300, 8)) + 0.123
    source = builder.AddSystem(held_signal(samples))
    rms = builder.AddSystem(RmsEnvelope(config=EnvelopeConfig(window=20)))
    builder.Connect(source.get_output_port(), rms.get_emg_input_port())
    out = simulate(builder, {"rms": rms.get_envelope_output_port()}, len(samples))["rms"][:, 0]
    np.testing.assert_allclose(out, brute_force_rms(samples, 20, False), rtol=1e-12)


def test_system_recovers_from_nan_after_one_window(builder, simulate, held_signal):
    samples = np.ones((100, 8))
    samples[30] = np.nan
    source = builder.AddSystem(held_signal(samples))
    rms = builder.AddSystem(RmsEnvelope(config=EnvelopeConfig(window=10)))
    builder.Connect(source.get_output_port(), rms.get_emg_input_port())
    out = simulate(builder, {"rms": rms.get_envelope_output_port()}, 100)["rms"][:, 0]
    assert np.all(np.isnan(out[30:40]))
    np.testing.assert_array_equal(out[40:], 8.0)


def test_clone_and_autodiff_derivative_by_hand():
    # One sample x in the window of L = 4: envelope = |sum x| / 2, d/dx_i = sign(sum x) / 2.
    system = RmsEnvelope(config=EnvelopeConfig(window=4))
    x = np.arange(8.0) - 2.0  # sum 12
    clone = system.Clone()
    context = clone.CreateDefaultContext()
    clone.get_input_port(0).FixValue(context, x)
    context.SetDiscreteState(clone.EvalUniquePeriodicDiscreteUpdate(context).get_vector().value())
    assert clone.get_output_port(0).Eval(context)[0] == 6.0
    ad = system.ToAutoDiffXd()
    context = ad.CreateDefaultContext()
    ad.get_emg_input_port().FixValue(context, InitializeAutoDiff(x))
    context.SetDiscreteState(ad.EvalUniquePeriodicDiscreteUpdate(context).get_vector().CopyToVector())
    envelope = ad.get_envelope_output_port().Eval(context)
    assert envelope[0].value() == pytest.approx(6.0, rel=1e-15)
    np.testing.assert_allclose(ExtractGradient(envelope), np.full((1, 8), 0.5), rtol=1e-15)
    assert isinstance(envelope[0], AutoDiffXd)


@pytest.mark.parametrize("window", [0, -3, 2.5, True])
def test_bad_window(window):
    with pytest.raises(ValueError, match="window"):
        moving_rms(np.zeros((5, 8)), window)
    with pytest.raises(ValueError, match="window"):
        RmsEnvelope(config=EnvelopeConfig(window=window))


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
    sample = np.linspace(-1e-4, 2e-4, 16)  # volts
    for per_channel in (False, True):
        builder = DiagramBuilder()
        source = builder.AddSystem(ConstantVectorSource(sample))
        config = EnvelopeConfig(window=5, per_channel=per_channel)
        rms = builder.AddSystem(RmsEnvelope(config=config, channels=16))
        builder.Connect(source.get_output_port(), rms.get_emg_input_port())
        simulator = Simulator(builder.Build())
        simulator.AdvanceTo(0.1)  # 20 samples: the window is full of the constant sample
        context = rms.GetMyContextFromRoot(simulator.get_context())
        envelope = rms.get_envelope_output_port().Eval(context)[0]
        # Each channel's RMS is |x_c|, summed; or the RMS of the constant sum, |sum x|.
        expected = np.sum(np.abs(sample)) if per_channel else abs(sample.sum())
        assert envelope == pytest.approx(expected, rel=1e-12)
    with pytest.raises(ValueError, match="channels must be a positive integer"):
        RmsEnvelope(channels=0)
