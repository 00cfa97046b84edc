"""The warning for states whose regression (eq. 16) makes eqs. 15-18 diverge."""

import warnings

import numpy as np
import pytest

from hemg_drake.learning.hsmm import HSMM
from hemg_drake.learning.reproduce import (
    HsmmGmrPolicy,
    check_gmr_stability,
    regression_growth_rates,
)


def exponential_demos(rate, n_demos=6, seed=0):
    """Deviations e(t) = e0 exp(rate t) about a point, velocity rate e: eq. 16's exact slope."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 0.2, 0.002)
    demos = []
    for _ in range(n_demos):
        e = rng.normal(0.0, 0.01, 3)[None, :] * np.exp(rate * t)[:, None]
        x = np.array([0.6, -0.8, 0.1]) + e
        k = 50.0 + rng.normal(0.0, 1.0, (len(t), 1))
        demos.append(np.hstack([x, rate * e, k]))
    return demos


@pytest.mark.parametrize("rate", [-5.0, 2.0, 20.0])
def test_growth_rate_is_the_slope_of_velocity_on_position(rate):
    model = HSMM(1, init="time", reg_covar=1e-6, n_iter=2, random_state=0).fit(exponential_demos(rate))
    # With xdot = rate (x - x0) exactly, the regression gain is rate I.
    assert regression_growth_rates(model) == pytest.approx([rate], abs=1e-3 * abs(rate))


def test_a_fast_growing_state_warns_once_for_the_gmr_tracker_only():
    unstable = HSMM(1, init="time", reg_covar=1e-6, n_iter=2, random_state=0).fit(
        exponential_demos(20.0))  # fmt: skip
    with pytest.warns(UserWarning, match=r"state 0's velocity regression .* \+20\.0 1/s"):
        HsmmGmrPolicy(unstable, weighting="temporal")
    stable = HSMM(1, init="time", reg_covar=1e-6, n_iter=2, random_state=0).fit(exponential_demos(2.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        HsmmGmrPolicy(stable, weighting="temporal")
        check_gmr_stability(unstable, limit=25.0)


def test_the_lqr_tracker_does_not_warn():
    from hemg_drake.learning.reproduce import HsmmLqrPolicy

    unstable = HSMM(1, init="time", reg_covar=1e-6, n_iter=2, random_state=0).fit(
        exponential_demos(20.0))  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        HsmmLqrPolicy(unstable, weighting="temporal")


def test_the_fastest_axis_of_the_fastest_state_is_reported():
    # Two states set by hand: state 1's regression is diag(20, -5, 1) 1/s in a rotated
    # frame, so only its largest eigenvalue, not its mean or its diagonal, gives 20.
    model = HSMM(2, init="time", reg_covar=1e-6, n_iter=2, random_state=0).fit(exponential_demos(-1.0))
    rotation = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]
    gain = rotation @ np.diag([20.0, -5.0, 1.0]) @ rotation.T
    S_xx = np.diag([4e-4, 1e-4, 9e-4])
    S = np.eye(7) * 1.0
    S[:3, :3] = S_xx
    S[3:6, :3] = gain @ S_xx  # S^{xdot x} = A S^{xx}
    S[:3, 3:6] = S[3:6, :3].T
    S[3:6, 3:6] = gain @ S_xx @ gain.T + 1e-3 * np.eye(3)
    model.covariances_[1] = S
    rates = regression_growth_rates(model)
    assert rates[1] == pytest.approx(20.0, rel=1e-9)
    assert rates[0] < 0  # the fitted decaying state
    with pytest.warns(UserWarning, match=r"state 1's velocity regression .* \+20\.0 1/s"):
        check_gmr_stability(model)
