"""Activation and gain law (eq. 22), offline and through the VariableGain system, against
values computed by hand."""

import math

import numpy as np
import pytest
from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff

from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.config import GainConfig
from hemg_drake.emg.gain import VariableGain, activation, gain_from_activation

K_MIN, K_MAX = 10.0, 100.0
CONFIG = GainConfig(k_min=K_MIN, k_max=K_MAX)

# Eq. 22 by hand with A_emg = -0.6981: exp(-0.6981) = 0.497530, and
# u = 0.25: exp(-0.174525) = 0.839856, a = 0.160144 / 0.502470 = 0.318714
# u = 0.5:  exp(-0.349050) = 0.705358, a = 0.294642 / 0.502470 = 0.586387
# u = 0.8:  exp(-0.558480) = 0.572078, a = 0.427922 / 0.502470 = 0.851637
# K = 10 + 90 a (a_rest = 0 -> K_min, a_mvc = 1 -> K_max).
HAND_POINTS = [(0.25, 0.318714, 38.6842), (0.5, 0.586387, 62.7748), (0.8, 0.851637, 86.6473)]


def _outputs(system, envelope, context=None):
    context = system.CreateDefaultContext() if context is None else context
    system.get_envelope_input_port().FixValue(context, [envelope])
    a = system.get_activation_output_port().Eval(context)[0]
    K = system.get_gain_output_port().Eval(context)[0]
    return a, K


@pytest.mark.parametrize("u, a_hand, K_hand", HAND_POINTS)
def test_eq22_at_hand_computed_points(u, a_hand, K_hand):
    assert activation(u) == pytest.approx(a_hand, abs=2e-6)
    assert gain_from_activation(a_hand, k_min=K_MIN, k_max=K_MAX) == pytest.approx(K_hand, abs=1e-4)
    a, K = _outputs(VariableGain(config=CONFIG), u)
    assert a == pytest.approx(a_hand, abs=2e-6)
    assert K == pytest.approx(K_hand, abs=1e-3)


def test_rest_gives_k_min_full_contraction_gives_k_max():
    system = VariableGain(config=CONFIG)
    assert _outputs(system, 0.0) == (0.0, K_MIN)
    a, K = _outputs(system, 1.0)
    assert a == pytest.approx(1.0, abs=1e-15) and K == pytest.approx(K_MAX, abs=1e-12)
    # Out of range envelopes are clipped, never extrapolated.
    assert _outputs(system, 3.0)[1] == pytest.approx(K_MAX)
    assert _outputs(system, -1.0) == (0.0, K_MIN)


def test_gain_is_monotonic_and_bounded_over_unit_interval():
    system = VariableGain(config=CONFIG)
    u = np.linspace(0.0, 1.0, 101)
    a, K = np.array([_outputs(system, value) for value in u]).T
    assert np.all(np.diff(a) > 0) and np.all(np.diff(K) > 0)
    assert K.min() >= K_MIN and K.max() <= K_MAX
    # A_emg < 0 makes a(u) concave: above the diagonal inside (0, 1).
    assert np.all(a[1:-1] > u[1:-1])


def test_paper_bound_naming_direction():
    # Paper: alpha_min is the upper bound (strongest contraction), alpha_max the lower.
    alpha_min, alpha_max = 0.9, 0.2
    K = gain_from_activation(
        [alpha_max, alpha_min], k_min=5.0, k_max=50.0, a_rest=alpha_max, a_mvc=alpha_min
    )
    np.testing.assert_allclose(K, [5.0, 50.0])


def test_calibration_inside_the_system_takes_raw_envelope():
    calibration = EmgCalibration(rest_level=10.0, mvc_level=90.0)
    system = VariableGain(config=CONFIG, calibration=calibration)
    assert _outputs(system, 10.0)[1] == K_MIN
    assert _outputs(system, 90.0)[1] == pytest.approx(K_MAX)
    # 50 -> u = 0.5 -> the hand value above.
    assert _outputs(system, 50.0)[1] == pytest.approx(HAND_POINTS[1][2], abs=1e-3)


def test_gains_and_levels_are_parameters_of_the_context():
    system = VariableGain(config=CONFIG)
    context = system.CreateDefaultContext()
    # K range 20..30 and levels 10..90 in this context only: u = 0.5 -> 20 + 10 a(0.5).
    system.set_parameters(context, config=GainConfig(k_min=20.0, k_max=30.0),
                          calibration=EmgCalibration(rest_level=10.0, mvc_level=90.0))  # fmt: skip
    assert _outputs(system, 50.0, context)[1] == pytest.approx(20 + 10 * 0.586387, abs=1e-5)
    assert _outputs(system, 0.5)[1] == pytest.approx(HAND_POINTS[1][2], abs=1e-3)
    clone = system.Clone()
    clone_context = clone.CreateDefaultContext()
    clone.get_input_port(0).FixValue(clone_context, [0.5])
    assert clone.get_output_port(1).Eval(clone_context)[0] == _outputs(system, 0.5)[1]


def test_autodiff_slope_by_hand():
    # dK/de = (K_max - K_min) A exp(A u) / (exp(A) - 1) / (mvc - rest), u = (e - rest) / (mvc - rest).
    calibration = EmgCalibration(rest_level=10.0, mvc_level=90.0)
    ad = VariableGain(config=CONFIG, calibration=calibration).ToAutoDiffXd()
    context = ad.CreateDefaultContext()
    ad.get_envelope_input_port().FixValue(context, InitializeAutoDiff(np.array([50.0])))
    A = -0.6981
    slope = 90.0 * A * math.exp(A * 0.5) / (math.exp(A) - 1.0) / 80.0
    gain = ad.get_gain_output_port().Eval(context)
    assert gain[0].value() == pytest.approx(HAND_POINTS[1][2], abs=1e-3)
    assert ExtractGradient(gain)[0, 0] == pytest.approx(slope, rel=1e-12)


@pytest.mark.parametrize("bad", [np.nan, -np.nan])
def test_nan_envelope_gives_k_min_and_no_nan(bad):
    a, K = _outputs(VariableGain(config=CONFIG), bad)
    assert (a, K) == (0.0, K_MIN)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"config": GainConfig(A_emg=0.0)}, "A_emg"),
        ({"config": GainConfig(A_emg=np.nan)}, "A_emg"),
        ({"config": GainConfig(k_min=50.0, k_max=50.0)}, "k_min < k_max"),
        ({"config": GainConfig(k_min=-1.0)}, "k_min"),
        ({"config": GainConfig(k_max=np.inf)}, "k_max"),
        ({"calibration": {"rest_level": 1.0}}, "EmgCalibration"),
    ],
)
def test_bad_parameters(kwargs, message):
    with pytest.raises(ValueError, match=message):
        VariableGain(**kwargs)


def test_bad_activation_bounds():
    with pytest.raises(ValueError, match="a_rest and a_mvc"):
        gain_from_activation(0.5, a_rest=0.3, a_mvc=0.3)
