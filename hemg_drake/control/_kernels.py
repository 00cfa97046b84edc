"""The 1 kHz arithmetic of the PD and the CLIK, compiled by numba.

Each controller's step is a dozen numpy expressions on 7-vectors, where numpy's per-call
overhead costs several times the arithmetic itself; one compiled call does the same sums in
the same order (``cache=True``: compiled once per machine). The numpy forms stay the
reference: ``pd_gains``/``pd_torque`` and ``Clik.qdot``, which the tests compare with these.
The CLIK's limits and its tool-axis task are checked against references written in the tests.
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
def _room_clipped(qdot, q_d, q_lower, q_upper, period, j):
    """Joint j's rate bounded by the room to its own position limits over one period."""
    return min(max(qdot[j], (q_lower[j] - q_d[j]) / period), (q_upper[j] - q_d[j]) / period)


@numba.njit(cache=True)
def limited_step_into(q_next, v_next, q_d, qdot, v_max, q_lower, q_upper, period):
    """One CLIK integration step within the position and velocity limits, into the buffers.

    First each joint's rate is bounded by the room to its own position limits over the step,
    ``(q_lower - q_d) / period <= rate <= (q_upper - q_d) / period``: a joint at a limit that
    ``qdot`` pushes further out stops, and only it. Then, if a joint still exceeds ``v_max``,
    all rates are scaled by one factor (direction kept). Finally q_next = q_d + period * rate
    (clipped to the limits against rounding) and v_next = (q_next - q_d) / period.
    """
    n = q_d.shape[0]
    ratio = 0.0
    for j in range(n):
        ratio = max(ratio, abs(_room_clipped(qdot, q_d, q_lower, q_upper, period, j)) / v_max[j])
    for j in range(n):
        r = _room_clipped(qdot, q_d, q_lower, q_upper, period, j)
        if ratio > 1.0:
            r = r / ratio
        q = min(max(q_d[j] + period * r, q_lower[j]), q_upper[j])
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


@numba.njit(cache=True)
def transpose_point_step_into(out, q_d, J, p_WE, p_desired, columns, gain, limits, period):
    """``transpose_step_into`` with e = p_desired - p_WE, into ``out`` (2, n): q_next, v_next.

    ``p_WE`` (3, 1) is the tool point (``CalcPointsPositions``), ``limits`` (3, n) v_max,
    q_lower, q_upper. Returns False (and ``out`` untouched) if p_desired holds a NaN or inf.
    """
    e = np.empty(3)
    for i in range(3):
        if not math.isfinite(p_desired[i]):
            return False
        e[i] = p_desired[i] - p_WE[i, 0]
    transpose_step_into(
        out[0], out[1], q_d, J, columns, e, gain, limits[0], limits[1], limits[2], period
    )
    return True


@numba.njit(cache=True)
def _solve3_into(x, A, b):
    """x = A^-1 b for a symmetric positive-definite 3x3 A, by Cholesky (A is not changed)."""
    l00 = math.sqrt(A[0, 0])
    l10 = A[1, 0] / l00
    l20 = A[2, 0] / l00
    l11 = math.sqrt(A[1, 1] - l10 * l10)
    l21 = (A[2, 1] - l20 * l10) / l11
    l22 = math.sqrt(A[2, 2] - l20 * l20 - l21 * l21)
    y0 = b[0] / l00
    y1 = (b[1] - l10 * y0) / l11
    y2 = (b[2] - l20 * y0 - l21 * y1) / l22
    x[2] = y2 / l22
    x[1] = (y1 - l21 * x[2]) / l11
    x[0] = (y0 - l10 * x[1] - l20 * x[2]) / l00


# The axis step's matrix-matrix products as loops: numba's ``@`` calls BLAS, whose per-call
# overhead (about 0.2 us) is several times these sums. Each sum runs from 0 in index order
# with fused multiply-adds ("contract"), as OpenBLAS's dgemm does at these sizes: the same
# bits as the ``@`` they replace. (No loop order matched its dgemv: matrix-vector products
# stay ``@``.)
@numba.njit(cache=True, fastmath={"contract"})
def _matmul_into(C, A, B):
    """C = A B (B may be a transposed view)."""
    for i in range(C.shape[0]):
        for j in range(C.shape[1]):
            total = 0.0
            for k in range(A.shape[1]):
                total += A[i, k] * B[k, j]
            C[i, j] = total


# Layout of axis_step_into's ``task`` array: the Clik's constants, packed once at
# construction (each argument of a compiled call costs about 0.04 us to unbox).
TASK_GAIN, TASK_DLS, TASK_DAMPING, TASK_AXIS_GAIN, TASK_AXIS_DAMPING, TASK_NULL_DAMPING = range(6)
TASK_PERIOD = 6
TASK_P_EOE_E, TASK_AXIS_E, TASK_AXIS_W = slice(7, 10), slice(10, 13), slice(13, 16)
TASK_SIZE = 16


@numba.njit(cache=True)
def axis_step_into(out, q_d, J, X_WE, p_desired, columns, task, limits):
    """The CLIK step with the tool-axis task in the position task's null space (``Clik``).

    ``J`` is the plant's (6, nv) spatial Jacobian of point E in W (rows: angular, then
    translational velocity), ``X_WE`` (4, 4) frame E's pose in W. With ``Jv``, ``Jw`` the
    arm's columns of the translational and angular rows, a = R_WE axis_E, d = axis_W::

        qdot_p = gain Jv^T e   or   gain Jv^T (Jv Jv^T + damping^2 I)^-1 e   (dls)
        N      = I - Jv^T (Jv Jv^T + null_damping^2 I)^-1 Jv
        P      = I - a a^T,  e_a = angle(a, d) (a x d) / |a x d|
        A      = P Jw N
        qdot   = qdot_p + A^T (A A^T + axis_damping^2 I)^-1 (axis_gain e_a - P Jw qdot_p)

    then the limited step. See ``Clik`` for the law's reasons.

    Parameters
    ----------
    out : array, shape (2, n), written: q_next, v_next (rad, rad/s).
    q_d : array, shape (n,), the reference before the step.
    J : array, shape (6, nv); X_WE : array, shape (4, 4); p_desired : array, shape (3,).
    columns : int array, shape (n,), the arm's velocities among the plant's.
    task : array, shape (TASK_SIZE,), the constants at the ``TASK_*`` indices: gain,
        dls (1.0 or 0.0), damping, axis_gain, axis_damping, null_damping, period,
        p_EoE_E, axis_E, axis_W (unit).
    limits : array, shape (3, n), v_max, q_lower, q_upper.

    Returns
    -------
    bool, False (and ``out`` untouched) if p_desired holds a NaN or inf.
    """
    for i in range(3):
        if not math.isfinite(p_desired[i]):
            return False
    gain, damping = task[TASK_GAIN], task[TASK_DAMPING]
    axis_gain, axis_damping = task[TASK_AXIS_GAIN], task[TASK_AXIS_DAMPING]
    null_damping = task[TASK_NULL_DAMPING]
    p_EoE_E, axis_E, axis_W_desired = task[TASK_P_EOE_E], task[TASK_AXIS_E], task[TASK_AXIS_W]
    n = q_d.shape[0]
    Jw = np.empty((3, n))
    Jv = np.empty((3, n))
    for j in range(n):
        c = columns[j]
        for i in range(3):
            Jw[i, j] = J[i, c]
            Jv[i, j] = J[3 + i, c]
    e = np.empty(3)
    a = np.empty(3)
    for i in range(3):
        e[i] = p_desired[i] - (
            X_WE[i, 3] + X_WE[i, 0] * p_EoE_E[0] + X_WE[i, 1] * p_EoE_E[1] + X_WE[i, 2] * p_EoE_E[2]
        )
        a[i] = X_WE[i, 0] * axis_E[0] + X_WE[i, 1] * axis_E[1] + X_WE[i, 2] * axis_E[2]
    # The position law, eq. 21.
    G = np.empty((3, 3))
    _matmul_into(G, Jv, Jv.T)
    y = np.empty(3)
    if task[TASK_DLS] != 0.0:
        Gd = G.copy()
        for i in range(3):
            Gd[i, i] += damping * damping
        _solve3_into(y, Gd, e)
    else:
        y[:] = e
    qdot = gain * (Jv.T @ y)
    # Jw N = Jw - (Jw Jv^T) (Jv Jv^T + null_damping^2 I)^-1 Jv, one 3x3 solve per column.
    for i in range(3):
        G[i, i] += null_damping * null_damping
    K = np.empty((3, 3))
    _matmul_into(K, Jw, Jv.T)
    JwN = Jw.copy()
    z = np.empty(3)
    for j in range(n):
        _solve3_into(z, G, Jv[:, j])
        for i in range(3):
            JwN[i, j] -= K[i, 0] * z[0] + K[i, 1] * z[1] + K[i, 2] * z[2]
    # P keeps the angular rates that move the axis (its roll about itself is left free).
    P = np.eye(3)
    for i in range(3):
        for k in range(3):
            P[i, k] -= a[i] * a[k]
    A = np.empty((3, n))
    _matmul_into(A, P, JwN)
    # Axis error: the rotation vector that turns a onto d.
    c0 = a[1] * axis_W_desired[2] - a[2] * axis_W_desired[1]
    c1 = a[2] * axis_W_desired[0] - a[0] * axis_W_desired[2]
    c2 = a[0] * axis_W_desired[1] - a[1] * axis_W_desired[0]
    s = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    cosine = a[0] * axis_W_desired[0] + a[1] * axis_W_desired[1] + a[2] * axis_W_desired[2]
    scale = math.atan2(s, cosine) / s if s > 1e-12 else 0.0
    r = np.empty(3)
    r[0], r[1], r[2] = axis_gain * scale * c0, axis_gain * scale * c1, axis_gain * scale * c2
    r -= P @ (Jw @ qdot)
    H = np.empty((3, 3))
    _matmul_into(H, A, A.T)
    for i in range(3):
        H[i, i] += axis_damping * axis_damping
    _solve3_into(z, H, r)
    qdot += A.T @ z
    limited_step_into(
        out[0], out[1], q_d, qdot, limits[0], limits[1], limits[2], task[TASK_PERIOD]
    )
    return True
