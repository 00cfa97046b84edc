"""The tracking LQR's Riccati recursion against hand-solved, DARE and brute-force references."""

import numpy as np
import pytest
import scipy.linalg

from hemg_drake.learning import lqr


def random_spd(rng, size, n=6):
    factors = rng.standard_normal((size, n, n))
    return factors @ np.swapaxes(factors, 1, 2) + 0.1 * np.eye(n)


def batch_controls(A, B, Q, Qm, R, s0):
    """All H controls by least squares over the whole trajectory (the batch LQR).

    s_t = A^t s_0 + sum_{j<t} A^(t-1-j) B u_j, so s = G u + g; the cost
    sum_t (s_t - m_t)^T Q_t (s_t - m_t) + sum_t u_t^T R u_t is a quadratic in u.
    """
    horizon, (n, m) = len(Q) - 1, B.shape
    G = np.zeros(((horizon + 1) * n, horizon * m))
    g = np.zeros((horizon + 1) * n)
    power = np.eye(n)
    for t in range(horizon + 1):
        g[t * n : (t + 1) * n] = power @ s0
        for j in range(t):
            G[t * n : (t + 1) * n, j * m : (j + 1) * m] = np.linalg.matrix_power(A, t - 1 - j) @ B
        power = A @ power
    Qbig = scipy.linalg.block_diag(*Q)
    reference = np.concatenate([np.linalg.solve(Q[t], Qm[t]) for t in range(horizon + 1)])
    hessian = G.T @ Qbig @ G + np.kron(np.eye(horizon), R)
    gradient = G.T @ Qbig @ (reference - g)
    return np.linalg.solve(hessian, gradient).reshape(horizon, m)


def test_double_integrator_is_exact_for_a_constant_acceleration():
    A, B = lqr.double_integrator(2, 0.1)
    s = np.array([1.0, -2.0, 0.5, 0.25])  # x, xdot
    u = np.array([3.0, -1.0])
    for _ in range(10):
        s = A @ s + B @ u
    t = 1.0  # 10 steps of 0.1 s: x0 + v0 t + a t^2 / 2, v0 + a t
    np.testing.assert_allclose(s[:2], [1.0 + 0.5 * t + 1.5 * t**2, -2.0 + 0.25 * t - 0.5 * t**2])
    np.testing.assert_allclose(s[2:], [0.5 + 3.0 * t, 0.25 - 1.0 * t])


def test_scalar_horizons_solved_by_hand():
    # x_{t+1} = x_t + u_t; cost Q_t (x_t - a_t)^2 + r u_t^2.
    A, B, R = np.eye(1), np.eye(1), np.array([[2.0]])
    q1, q2, a1, a2 = 3.0, 5.0, 0.4, 1.0
    # One step: min 2 u^2 + 5 (x + u - 1)^2 gives u = 5 (1 - x) / 7.
    K, k = lqr.tracking_gains(A, B, [[[1.0]], [[q2]]], [[0.0], [q2 * a2]], R)
    np.testing.assert_allclose(K[0], [[5.0 / 7.0]])
    np.testing.assert_allclose(k[0], [5.0 / 7.0])
    # Two steps: the cost-to-go after one step is P_1 = q1 + r q2 / (r + q2) = 3 + 10 / 7,
    # with linear term q_1 = q1 a1 + r q2 a2 / (r + q2) = 1.2 + 10 / 7.
    K, k = lqr.tracking_gains(A, B, [[[0.0]], [[q1]], [[q2]]], [[0.0], [q1 * a1], [q2 * a2]], R)
    P1, q1_linear = 3.0 + 10.0 / 7.0, 1.2 + 10.0 / 7.0
    np.testing.assert_allclose(K[0], [[P1 / (2.0 + P1)]])
    np.testing.assert_allclose(k[0], [q1_linear / (2.0 + P1)])
    np.testing.assert_allclose(K[1], [[5.0 / 7.0]])


def test_a_long_horizon_with_a_constant_cost_gives_the_dare_gain():
    rng = np.random.default_rng(0)
    A, B = lqr.double_integrator(3, 0.01)
    Q = random_spd(rng, 1)[0] * 100.0
    R = np.diag([1.0, 2.0, 0.5])
    K, _ = lqr.tracking_gains(A, B, np.broadcast_to(Q, (3001, 6, 6)), np.zeros((3001, 6)), R)
    P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    K_inf = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    np.testing.assert_allclose(K[0], K_inf, rtol=1e-8, atol=1e-10)


def test_the_recursion_equals_the_batch_least_squares_solution():
    rng = np.random.default_rng(1)
    A, B = lqr.double_integrator(2, 0.05)
    Q = random_spd(rng, 7, 4)
    Qm = np.einsum("tij,tj->ti", Q, rng.standard_normal((7, 4)))
    R = np.array([[0.3, 0.1], [0.1, 0.2]])
    s0 = rng.standard_normal(4)
    K, k = lqr.tracking_gains(A, B, Q, Qm, R)
    _, controls = lqr.rollout(A, B, K, k, s0)
    expected = batch_controls(A, B, Q, Qm, R, s0)
    np.testing.assert_allclose(controls, expected, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(lqr.first_control(A, B, Q, Qm, R, s0), expected[0], atol=1e-9)


def test_a_singular_cost_step_is_accepted():
    # A cost on the position alone at some steps (Q_t singular), as a mixture can give.
    rng = np.random.default_rng(2)
    A, B = lqr.double_integrator(1, 0.1)
    Q = np.array([np.diag([1.0, 1.0]), np.diag([4.0, 0.0]), np.diag([2.0, 3.0])])
    Qm = np.array([[0.0, 0.0], [4.0 * 0.3, 0.0], [2.0 * 0.5, 0.0]])
    s0 = rng.standard_normal(2)
    K, k = lqr.tracking_gains(A, B, Q, Qm, np.eye(1))
    _, controls = lqr.rollout(A, B, K, k, s0)
    # Brute force on a fine grid of (u_0, u_1) around the optimum.
    def cost(u):
        s, total = s0, 0.0
        for t in range(2):
            s = A @ s + B @ u[t : t + 1]
            total += s @ Q[t + 1] @ s - 2.0 * s @ Qm[t + 1] + u[t] ** 2
        return total

    best = controls[:, 0]
    for delta in ([1e-3, 0], [-1e-3, 0], [0, 1e-3], [0, -1e-3]):
        assert cost(best + np.array(delta)) > cost(best)


def test_batches_of_horizons_are_solved_one_by_one():
    rng = np.random.default_rng(3)
    A, B = lqr.double_integrator(3, 0.01)
    Q = random_spd(rng, 4 * 6).reshape(4, 6, 6, 6)
    Qm = rng.standard_normal((4, 6, 6))
    R = np.eye(3)
    K, k = lqr.tracking_gains(A, B, Q, Qm, R)
    first_K, first_k = lqr.tracking_gains(A, B, Q, Qm, R, first_only=True)
    for b in range(4):
        K_b, k_b = lqr.tracking_gains(A, B, Q[b], Qm[b], R)
        np.testing.assert_allclose(K[b], K_b, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(k[b], k_b, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(first_K[b], K_b[0], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(first_k[b], k_b[0], rtol=1e-12, atol=1e-12)


def test_an_empty_horizon_is_rejected():
    A, B = lqr.double_integrator(1, 0.1)
    with pytest.raises(ValueError, match="at least 1 step"):
        lqr.tracking_gains(A, B, np.eye(2)[None], np.zeros((1, 2)), np.eye(1))
