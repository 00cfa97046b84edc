"""The compiled 1 kHz steps of the PD and the CLIK against their numpy references."""

import numpy as np
import pytest

from hemg_drake.control._kernels import (
    limited_step_into,
    pd_torque_into,
    transpose_step_into,
)
from hemg_drake.control.pd import STIFFNESS_SCALE, pd_gains, pd_torque

N, NV = 7, 9  # the arm's joints among a plant's velocities (e.g. a scene in front)
COLUMNS = np.arange(1, 1 + N)


@pytest.fixture
def rng():
    return np.random.default_rng(7)


@pytest.mark.parametrize("gravity", [True, False])
def test_pd_kernel_equals_pd_gains_and_pd_torque_to_the_bit(rng, gravity):
    limit = np.array([50.0, 50.0, 50.0, 50.0, 15.0, 15.0, 15.0])
    for _ in range(50):
        x, q_d, v_d = rng.normal(size=2 * N), rng.normal(size=N), rng.normal(size=N)
        A = rng.normal(size=(NV, NV))
        M = A @ A.T + NV * np.eye(NV)
        g = rng.normal(0.0, 20.0, NV) if gravity else np.zeros(0)
        gain, zeta = rng.uniform(5.0, 500.0), rng.uniform(0.5, 1.5)
        kp, kd = pd_gains(gain, STIFFNESS_SCALE, M.diagonal()[COLUMNS], zeta)
        expected = pd_torque(
            x[:N], x[N:], q_d, v_d, kp, kd, limit, -g[COLUMNS] if gravity else 0.0
        )
        out = np.full(N, np.nan)
        assert pd_torque_into(out, x, q_d, v_d, gain, STIFFNESS_SCALE, zeta, M, g, COLUMNS, limit)
        np.testing.assert_array_equal(out, expected)
    assert np.any(np.abs(expected) == limit), "some torques should saturate"


def test_pd_kernel_rejects_nan_references():
    out = np.zeros(N)
    q_d = np.zeros(N)
    q_d[3] = np.nan
    args = (1.0, STIFFNESS_SCALE, 1.0, np.eye(NV), np.zeros(NV), COLUMNS, np.ones(N))
    assert not pd_torque_into(out, np.zeros(2 * N), q_d, np.zeros(N), *args)
    assert not pd_torque_into(out, np.zeros(2 * N), np.zeros(N), np.full(N, np.inf), *args)


def test_clik_limited_step_keeps_the_limits_invariants(rng):
    """Brute-force check of the limits' invariants on random steps (the per-joint rule itself
    is checked in a simulator in test_clik.py), and the transpose step = J^T e + that step."""
    v_max = np.array([1.5, 1.5, 1.5, 1.5, 4.0, 4.0, 4.0])
    q_lower, q_upper = np.full(N, -1.0), np.full(N, 1.0)
    gain, period = 300.0, 1e-2
    pinned = scaled = kept = 0
    for i in range(300):
        # Some joints exactly at a limit, others near one or anywhere; errors small and large.
        q_d = rng.uniform(-1.0, 1.0, N)
        at_limit = rng.random(N) < (0.4 if i % 2 else 0.1)
        q_d[at_limit] = rng.choice([-1.0, 1.0], N)[at_limit]
        J = rng.normal(size=(3, NV))
        e = rng.normal(0.0, (0.05, 0.002, 0.0002)[i % 3], 3)
        qdot = gain * J[:, COLUMNS].T @ e
        q_next, v_next = np.full(N, np.nan), np.full(N, np.nan)
        limited_step_into(q_next, v_next, q_d, qdot, v_max, q_lower, q_upper, period)

        assert np.all((q_next >= q_lower) & (q_next <= q_upper))
        assert np.all(np.abs(v_next) <= v_max * (1 + 1e-12))
        np.testing.assert_allclose(q_next, q_d + period * v_next, rtol=0, atol=1e-15)
        outward = ((q_d >= q_upper) & (qdot > 0)) | ((q_d <= q_lower) & (qdot < 0))
        assert np.all(v_next[outward] == 0.0)
        # Never faster than the law, never against it.
        assert np.all(np.abs(v_next) <= np.abs(qdot) + 1e-12)
        assert np.all((v_next * qdot >= 0.0) | (np.abs(v_next) < 1e-12))
        # The joints the position limits leave alone share one scale factor s <= 1 ...
        lands_inside = (q_d + period * qdot <= q_upper) & (q_d + period * qdot >= q_lower)
        free = ~outward & lands_inside & (qdot != 0.0)
        # (v_next = (q_next - q_d) / period rounds to ~1e-14 rad/s.)
        if free.any():
            big = np.argmax(np.abs(qdot) * free)
            s = v_next[big] / qdot[big]
            np.testing.assert_allclose(v_next[free], s * qdot[free], rtol=0, atol=1e-12)
            # ... which is 1 when nothing but the pinned joints exceeds a velocity limit ...
            if np.all(outward | lands_inside) and np.all(np.abs(qdot[~outward]) <= v_max[~outward]):
                np.testing.assert_allclose(v_next[free], qdot[free], rtol=0, atol=1e-12)
                kept += outward.any()
            # ... and no smaller than it must be: some joint ends at a velocity limit.
            elif s < 1.0 - 1e-9:
                assert np.isclose(np.abs(v_next) / v_max, 1.0, rtol=1e-12).any()
                scaled += 1
        pinned += outward.any()

        # The transpose law sums J^T e in its own order: equal to rounding.
        q_t, v_t = np.zeros(N), np.zeros(N)
        transpose_step_into(q_t, v_t, q_d, J, COLUMNS, e, gain, v_max, q_lower, q_upper, period)
        np.testing.assert_allclose(q_t, q_next, rtol=0, atol=1e-14)
        np.testing.assert_allclose(v_t, v_next, rtol=0, atol=1e-10)
    assert pinned > 50 and scaled > 20 and kept > 10, "each case should be exercised"
