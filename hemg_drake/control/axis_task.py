"""The tool-axis task of :class:`~hemg_drake.control.clik.Clik` and the 3x3 algebra both
its laws use, written out term by term for floats and AutoDiffXd alike (at 1 kHz each
numpy call counts)."""

import math

import numpy as np

# Damping mu of the tool-axis task's solve (dimensionless, as J_w). The task's two singular
# values are about 0.9 and 0.4 over a sheet within reach, so mu slows the axis there by 1-6 %.
# Where the arm cannot turn the axis further (the edge of its reach with the pen vertical, a
# wrist singularity) a singular value goes to 0 and mu bounds the joint rates: at 0.05 the
# arm swung out of that fold fast enough to lift the pen off the default sheet for 20 ms,
# at 0.1 it does not (benchmarks/bench_clik.py).
AXIS_DAMPING = 0.1
# Damping of the position Jacobian in the null-space projector (m): J J^T's eigenvalues are
# 0.1 to 2 m^2 over the workspace, so N leaks at most ~1e-7 of the axis task into the tool
# point's velocity, and N stays bounded at a singularity.
NULL_SPACE_DAMPING = 1e-4


def axis_task_rates(
    J, X_WE, p_WE_desired, *, gain, dls_damping, axis_gain, p_EoE_E, axis_E, axis_W,
    sqrt=math.sqrt,
):
    """The CLIK rates with the tool-axis task in the position task's null space (``Clik``).

    With ``Jw``, ``Jv`` the angular and translational rows of ``J``, a = R_WE axis_E,
    d = axis_W::

        qdot_p = gain Jv^T y,  y = e  or  (Jv Jv^T + dls_damping^2 I)^-1 e   (dls)
        N      = I - Jv^T (Jv Jv^T + nu^2 I)^-1 Jv            (nu = NULL_SPACE_DAMPING)
        P      = I - a a^T,  e_a = angle(a, d) (a x d) / |a x d|
        A      = P Jw N
        qdot   = qdot_p + A^T (A A^T + mu^2 I)^-1 (axis_gain e_a - P Jw qdot_p)

    Computed in 3x3 blocks of J J^T, one product with the 6 x n Jacobian in and one out
    (n-vectors cost a numpy call each): with G = Jv Jv^T, K = Jw Jv^T,
    L = K (G + nu^2 I)^-1 and B = Jw N = Jw - L Jv,
    B B^T = Jw Jw^T - L K^T - nu^2 L L^T (as L G L^T = L K^T - nu^2 L L^T), A A^T = P B B^T P,
    and with w = P (A A^T + mu^2 I)^-1 (...), qdot = J^T [w; gain y - L^T w].
    3x3 matrices are row-major 9-tuples of scalars (floats or AutoDiffXd), written out
    term by term: at 1 kHz each Python call and loop counts.

    Parameters
    ----------
    J : array, shape (6, n), the spatial Jacobian of point E in W (angular rows first).
    X_WE : sequence of 16 scalars, frame E's pose in W as a row-major 4x4 matrix.
    p_WE_desired : sequence of 3 scalars.
    gain, axis_gain : scalars; dls_damping : scalar, or None for the transpose law.
    p_EoE_E, axis_E, axis_W : sequences of 3 (axis_E, axis_W unit).
    sqrt : the square root of the scalar type.

    Returns
    -------
    list of n scalars, rad/s, before the limits.
    """
    (s00, s01, s02, k00, k01, k02), (_, s11, s12, k10, k11, k12), (
        _, _, s22, k20, k21, k22), (_, _, _, g00, g01, g02), (_, _, _, _, g11, g12), (
        _, _, _, _, _, g22) = (J @ J.T).tolist()  # fmt: skip
    R = (*X_WE[0:3], *X_WE[4:7], *X_WE[8:11])
    p0, p1, p2 = mv3(R, p_EoE_E)
    q0, q1, q2 = X_WE[3], X_WE[7], X_WE[11]
    d0, d1, d2 = p_WE_desired
    y = (d0 - (q0 + p0), d1 - (q1 + p1), d2 - (q2 + p2))  # e
    a0, a1, a2 = mv3(R, axis_E)
    G = (g00, g01, g02, g01, g11, g12, g02, g12, g22)
    if dls_damping is not None:
        y = mv3(inverse3(G, dls_damping * dls_damping), y)
    nu2 = NULL_SPACE_DAMPING * NULL_SPACE_DAMPING
    K = (k00, k01, k02, k10, k11, k12, k20, k21, k22)
    l00, l01, l02, l10, l11, l12, l20, l21, l22 = L = mm3(K, inverse3(G, nu2))
    # X = B B^T = S_ww - L K^T - nu^2 L L^T (symmetric: six entries).
    x00 = s00 - (l00 * k00 + l01 * k01 + l02 * k02) - nu2 * (l00 * l00 + l01 * l01 + l02 * l02)
    x01 = s01 - (l00 * k10 + l01 * k11 + l02 * k12) - nu2 * (l00 * l10 + l01 * l11 + l02 * l12)
    x02 = s02 - (l00 * k20 + l01 * k21 + l02 * k22) - nu2 * (l00 * l20 + l01 * l21 + l02 * l22)
    x11 = s11 - (l10 * k10 + l11 * k11 + l12 * k12) - nu2 * (l10 * l10 + l11 * l11 + l12 * l12)
    x12 = s12 - (l10 * k20 + l11 * k21 + l12 * k22) - nu2 * (l10 * l20 + l11 * l21 + l12 * l22)
    x22 = s22 - (l20 * k20 + l21 * k21 + l22 * k22) - nu2 * (l20 * l20 + l21 * l21 + l22 * l22)
    # H = P X P with P = I - a a^T: X - a (X a)^T - (X a) a^T + (a^T X a) a a^T.
    xa0 = x00 * a0 + x01 * a1 + x02 * a2
    xa1 = x01 * a0 + x11 * a1 + x12 * a2
    xa2 = x02 * a0 + x12 * a1 + x22 * a2
    axa = a0 * xa0 + a1 * xa1 + a2 * xa2
    h00 = x00 - 2.0 * a0 * xa0 + axa * a0 * a0
    h01 = x01 - a0 * xa1 - xa0 * a1 + axa * a0 * a1
    h02 = x02 - a0 * xa2 - xa0 * a2 + axa * a0 * a2
    h11 = x11 - 2.0 * a1 * xa1 + axa * a1 * a1
    h12 = x12 - a1 * xa2 - xa1 * a2 + axa * a1 * a2
    h22 = x22 - 2.0 * a2 * xa2 + axa * a2 * a2
    H = (h00, h01, h02, h01, h11, h12, h02, h12, h22)
    # Axis error: the rotation vector that turns a onto d.
    d0, d1, d2 = axis_W
    c0, c1, c2 = a1 * d2 - a2 * d1, a2 * d0 - a0 * d2, a0 * d1 - a1 * d0
    s = sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    cosine = a0 * d0 + a1 * d1 + a2 * d2
    scale = axis_gain * atan2(s, cosine) / s if s > 1e-12 else 0.0 * s
    # r = axis_gain e_a - P Jw qdot_p, with Jw qdot_p = gain K y and P v = v - a (a^T v).
    k0, k1, k2 = mv3(K, y)
    k0, k1, k2 = gain * k0, gain * k1, gain * k2
    ak = a0 * k0 + a1 * k1 + a2 * k2
    r = (scale * c0 - (k0 - a0 * ak), scale * c1 - (k1 - a1 * ak), scale * c2 - (k2 - a2 * ak))
    z0, z1, z2 = mv3(inverse3(H, AXIS_DAMPING * AXIS_DAMPING), r)
    az = a0 * z0 + a1 * z1 + a2 * z2
    w0, w1, w2 = z0 - a0 * az, z1 - a1 * az, z2 - a2 * az
    # L^T w.
    m0 = l00 * w0 + l10 * w1 + l20 * w2
    m1 = l01 * w0 + l11 * w1 + l21 * w2
    m2 = l02 * w0 + l12 * w1 + l22 * w2
    u = np.array([w0, w1, w2, gain * y[0] - m0, gain * y[1] - m1, gain * y[2] - m2])
    return (u @ J).tolist()


def mv3(A, x):
    """A x for a row-major 3x3 9-tuple and a 3-sequence."""
    x0, x1, x2 = x
    return (
        A[0] * x0 + A[1] * x1 + A[2] * x2,
        A[3] * x0 + A[4] * x1 + A[5] * x2,
        A[6] * x0 + A[7] * x1 + A[8] * x2,
    )


def mm3(A, B):
    """A B for row-major 3x3 9-tuples."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = B
    return (
        a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
        a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
        a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8,
    )  # fmt: skip


def inverse3(G, damping_squared):
    """(G + damping_squared I)^-1 for a symmetric 3x3 G (row-major 9-tuple), by its adjugate.

    Written out: ``np.linalg.inv`` costs more than these sums at this size and takes no
    AutoDiffXd.
    """
    g00, g01, g02, _, g11, g12, _, _, g22 = G
    g00, g11, g22 = g00 + damping_squared, g11 + damping_squared, g22 + damping_squared
    c00 = g11 * g22 - g12 * g12
    c01 = g02 * g12 - g01 * g22
    c02 = g01 * g12 - g02 * g11
    c11 = g00 * g22 - g02 * g02
    c12 = g01 * g02 - g00 * g12
    c22 = g00 * g11 - g01 * g01
    inverse_det = 1.0 / (g00 * c00 + g01 * c01 + g02 * c02)
    c00, c01, c02 = c00 * inverse_det, c01 * inverse_det, c02 * inverse_det
    c11, c12, c22 = c11 * inverse_det, c12 * inverse_det, c22 * inverse_det
    return (c00, c01, c02, c01, c11, c12, c02, c12, c22)


def atan2(y, x):
    """atan2 of floats (math's) or AutoDiffXd (Drake's)."""
    if isinstance(y, float) and isinstance(x, float):
        return math.atan2(y, x)
    from pydrake.math import atan2 as scalar_atan2

    return scalar_atan2(y, x)
