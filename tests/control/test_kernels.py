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


def _numpy_limited_step(q_d, qdot, v_max, q_lower, q_upper, period):
    ratio = (np.abs(qdot) / v_max).max()
    if ratio > 1.0:
        qdot = qdot / ratio
    q_next = np.minimum(np.maximum(q_d + period * qdot, q_lower), q_upper)
    return q_next, (q_next - q_d) / period


def test_clik_steps_equal_numpy(rng):
    v_max = np.full(N, 2.0)
    q_lower, q_upper = np.full(N, -1.0), np.full(N, 1.0)
    limited = clipped = 0
    for i in range(200):
        # Every other reference next to a position limit; errors small and large.
        q_d = rng.uniform(-1.0, 1.0, N) if i % 2 else rng.choice([-0.995, 0.995], N)
        J = rng.normal(size=(3, NV))
        e = rng.normal(0.0, 0.05 if i % 3 else 0.001, 3)
        gain, period = 300.0, 1e-2
        qdot = gain * J[:, COLUMNS].T @ e
        expected = _numpy_limited_step(q_d, qdot, v_max, q_lower, q_upper, period)
        q_next, v_next = np.zeros(N), np.zeros(N)
        limited_step_into(q_next, v_next, q_d, qdot, v_max, q_lower, q_upper, period)
        np.testing.assert_array_equal(q_next, expected[0])
        np.testing.assert_array_equal(v_next, expected[1])
        # The transpose law sums J^T e in its own order: equal to rounding.
        transpose_step_into(
            q_next, v_next, q_d, J, COLUMNS, e, gain, v_max, q_lower, q_upper, period
        )
        np.testing.assert_allclose(q_next, expected[0], rtol=0, atol=1e-14)
        np.testing.assert_allclose(v_next, expected[1], rtol=0, atol=1e-12)
        limited += np.abs(qdot).max() > 2.0
        clipped += np.any((q_next == q_lower) | (q_next == q_upper))
    assert limited > 20 and clipped > 20, "both limits should be exercised"
