"""Finite-horizon LQR tracking on a discrete double integrator (backward Riccati recursion).

Pure numpy, used by the tracking reproduction (:mod:`hemg_drake.learning.reproduce`,
``tracker="lqr"``). The state is s = [x (P), xdot (P)], the control u the acceleration
(P), held over each step of dt seconds (zero-order hold, exact):

    x_{t+1} = x_t + dt xdot_t + dt^2 / 2 u_t,    xdot_{t+1} = xdot_t + dt u_t.

Over a horizon of H steps the cost is

    J = sum_{t=0}^{H} (s_t - m_t)^T Q_t (s_t - m_t) + sum_{t=0}^{H-1} u_t^T R u_t,

given by Q_t and the "information" vector Q_t m_t, never m_t itself: a cost that is a
weighted sum of several Gaussians' quadratic forms sum_i h_i (s - mu_i)^T Lambda_i (s - mu_i)
is, up to a constant, Q = sum_i h_i Lambda_i and Q m = sum_i h_i Lambda_i mu_i, and Q may
be singular. The optimal control is affine in the state, u_t = k_t - K_t s_t, with the
value function V_t(s) = s^T P_t s - 2 s^T q_t + const from P_H = Q_H, q_H = Q_H m_H and

    S_t = R + B^T P_{t+1} B
    K_t = S_t^-1 B^T P_{t+1} A,          k_t = S_t^-1 B^T q_{t+1}
    P_t = Q_t + A^T P_{t+1} (A - B K_t)
    q_t = Q_t m_t + (A - B K_t)^T q_{t+1}.

Every function takes leading batch dimensions, so many horizons are solved at once.
"""

import numpy as np


def double_integrator(n_position, dt):
    """A (2P, 2P) and B (2P, P) of the zero-order-hold double integrator, state [x, xdot].

    Parameters
    ----------
    n_position : int
        P, the number of axes.
    dt : float
        Step in s.

    Returns
    -------
    A : array, shape (2P, 2P)
    B : array, shape (2P, P)
    """
    eye = np.eye(n_position)
    zero = np.zeros((n_position, n_position))
    A = np.block([[eye, dt * eye], [zero, eye]])
    B = np.vstack([0.5 * dt**2 * eye, dt * eye])
    return A, B


def tracking_gains(A, B, Q, Qm, R, *, first_only=False):
    """Backward Riccati recursion of the tracking LQR over one or many horizons.

    Parameters
    ----------
    A : array, shape (n, n)
    B : array, shape (n, m)
    Q : array, shape (..., H + 1, n, n)
        State cost at t = 0 .. H, symmetric positive semi-definite (Q_0 does not change
        the controls; it is accepted so that a horizon is one slice of a sequence).
    Qm : array, shape (..., H + 1, n)
        Q_t m_t, m_t the reference.
    R : array, shape (m, m)
        Control cost, symmetric positive definite.
    first_only : bool
        Return the gains of t = 0 only (what a receding-horizon controller applies), shapes
        (..., m, n) and (..., m).

    Returns
    -------
    K : array, shape (..., H, m, n)
        Feedback gains.
    k : array, shape (..., H, m)
        Feedforward terms: u_t = k_t - K_t s_t is optimal.
    """
    Q = np.asarray(Q, dtype=float)
    Qm = np.asarray(Qm, dtype=float)
    horizon = Q.shape[-3] - 1
    n, m = B.shape
    if horizon < 1:
        raise ValueError(f"the horizon must have at least 1 step, got Q of shape {Q.shape}")
    # The affine recursion as a linear one on z = [s, 1] (fewer numpy calls, which is what a
    # step costs at this size): V_t(z) = z^T [[P_t, -q_t], [-q_t^T, c_t]] z, and the gain on
    # z is [K_t, -k_t].
    batch = Q.shape[:-3]
    A_z = np.eye(n + 1)
    A_z[:n, :n] = A
    B_z = np.zeros((n + 1, m))
    B_z[:n] = B
    A_zT, B_zT = A_z.T, B_z.T
    Q_z = np.zeros((*batch, horizon + 1, n + 1, n + 1))
    Q_z[..., :n, :n] = Q
    Q_z[..., :n, n] = -Qm
    Q_z[..., n, :n] = -Qm
    if not first_only:
        K = np.empty((*batch, horizon, m, n))
        k = np.empty((*batch, horizon, m))
    P = Q_z[..., horizon, :, :]
    for t in range(horizon - 1, -1, -1):
        PB = P @ B_z  # (..., n + 1, m)
        gain = np.linalg.solve(R + B_zT @ PB, np.swapaxes(PB, -1, -2) @ A_z)
        if first_only:
            if t == 0:
                return gain[..., :n], -gain[..., n]
        else:
            K[..., t, :, :] = gain[..., :n]
            k[..., t, :] = -gain[..., n]
        # P_t = Q_t + A^T (P A - P B S^-1 B^T P A), symmetrised against rounding.
        P = Q_z[..., t, :, :] + A_zT @ (P @ A_z - PB @ gain)
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
    return K, k


def first_control(A, B, Q, Qm, R, s0):
    """u_0 = k_0 - K_0 s_0, the first control of the optimal plan from s_0.

    Parameters
    ----------
    A, B, Q, Qm, R : as in :func:`tracking_gains`.
    s0 : array, shape (..., n)

    Returns
    -------
    array, shape (..., m)
    """
    K, k = tracking_gains(A, B, Q, Qm, R, first_only=True)
    return k - (K @ np.asarray(s0)[..., None])[..., 0]


def rollout(A, B, K, k, s0):
    """States and controls of the closed loop u_t = k_t - K_t s_t from s_0.

    Parameters
    ----------
    A, B : as in :func:`tracking_gains`.
    K : array, shape (H, m, n)
    k : array, shape (H, m)
    s0 : array, shape (n,)

    Returns
    -------
    states : array, shape (H + 1, n)
    controls : array, shape (H, m)
    """
    horizon = len(k)
    states = np.empty((horizon + 1, len(s0)))
    controls = np.empty((horizon, B.shape[1]))
    states[0] = s0
    for t in range(horizon):
        controls[t] = k[t] - K[t] @ states[t]
        states[t + 1] = A @ states[t] + B @ controls[t]
    return states, controls
