"""The 1 kHz arithmetic of the PD and the CLIK, compiled by numba.

Each controller's step is a dozen numpy expressions on 7-vectors, where numpy's per-call
overhead costs several times the arithmetic itself; one compiled call does the same sums in
the same order (``cache=True``: compiled once per machine). The numpy forms stay the
reference: ``pd_gains``/``pd_torque`` and ``Clik.qdot``, which the tests compare with these.
"""

import math

import numba
import numpy as np


@numba.njit(cache=True)
def pd_torque_into(
    out, x, q_desired, v_desired, gain, stiffness_scale, damping_ratio, M, g, columns, limit
):
    """``pd_torque(q, v, q_d, v_d, *pd_gains(...), limit, -g)`` for one arm, into ``out``.

    Parameters
    ----------
    out : array, shape (n,), written.
    x : array, shape (2n,), the arm's [q; v].
    q_desired, v_desired : arrays, shape (n,).
    gain, damping_ratio : float, K and zeta.
    stiffness_scale, limit : arrays, shape (n,).
    M : array, (nv, nv), the plant's mass matrix; g : array, (nv,), its gravity forces (the
        gravity-compensating torque is -g), or shape (0,) for none.
    columns : int array, shape (n,), the arm's velocities among the plant's.

    Returns
    -------
    bool, False (and ``out`` untouched) if q_desired or v_desired holds a NaN or inf.
    """
    n = q_desired.shape[0]
    for j in range(n):
        if not (math.isfinite(q_desired[j]) and math.isfinite(v_desired[j])):
            return False
    twice_zeta = 2.0 * damping_ratio
    for j in range(n):
        c = columns[j]
        kp = gain * stiffness_scale[j]
        kd = twice_zeta * math.sqrt(kp * M[c, c])
        tau = kp * (q_desired[j] - x[j]) + kd * (v_desired[j] - x[n + j])
        if g.shape[0] > 0:
            tau = tau + -g[c]
        out[j] = min(max(tau, -limit[j]), limit[j])
    return True


@numba.njit(cache=True)
def limited_step_into(q_next, v_next, q_d, qdot, v_max, q_lower, q_upper, period):
    """One CLIK integration step within the velocity and position limits.

    qdot is scaled uniformly (direction kept) so that no joint exceeds ``v_max``, then
    q_next = clip(q_d + period * qdot, q_lower, q_upper) and v_next = (q_next - q_d) / period.
    """
    n = q_d.shape[0]
    ratio = 0.0
    for j in range(n):
        ratio = max(ratio, abs(qdot[j]) / v_max[j])
    for j in range(n):
        rate = qdot[j] / ratio if ratio > 1.0 else qdot[j]
        q = min(max(q_d[j] + period * rate, q_lower[j]), q_upper[j])
        q_next[j] = q
        v_next[j] = (q - q_d[j]) / period


@numba.njit(cache=True)
def transpose_step_into(
    q_next, v_next, q_d, J, columns, e, gain, v_max, q_lower, q_upper, period
):
    """The transpose-law CLIK step: qdot = gain * J[:, columns]^T e, then the limited step.

    ``J`` is the plant's (3, nv) translational Jacobian, ``e`` (3,) the position error.
    """
    n = q_d.shape[0]
    qdot = np.empty(n)
    for j in range(n):
        c = columns[j]
        qdot[j] = gain * (J[0, c] * e[0] + J[1, c] * e[1] + J[2, c] * e[2])
    limited_step_into(q_next, v_next, q_d, qdot, v_max, q_lower, q_upper, period)
