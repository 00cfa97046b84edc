"""Dynamic time warping (DTW) of two trajectories: the one implementation, used by the
learning's alignment (learning/align.py, ``learning.align: dtw``) and by the reproduction
metrics (tasks/metrics.py: Table II after DTW, the timing error, the mean demonstration).
"""

import numba
import numpy as np


def as_trajectory(name, values, width=None):
    """``values`` as a float array (T >= 2, D) of finite values (1-D: one column), ``width``
    columns if given; ValueError naming ``name`` otherwise."""
    values = np.asarray(values, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    if values.ndim != 2 or len(values) < 2:
        raise ValueError(f"{name} must have shape (T >= 2, D), got {np.shape(values)}")
    if width is not None and values.shape[1] != width:
        raise ValueError(f"{name} must have {width} columns, got shape {values.shape}")
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name} contains NaN or inf")
    return values


@numba.njit(cache=True)
def _dtw_path(a, b):
    """Warping path minimising the summed Euclidean distances; indices from (0, 0)."""
    n, m = a.shape[0], b.shape[0]
    cost = np.full((n + 1, m + 1), np.inf)
    cost[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            distance = 0.0
            for d in range(a.shape[1]):
                distance += (a[i - 1, d] - b[j - 1, d]) ** 2
            cost[i, j] = np.sqrt(distance) + min(cost[i - 1, j - 1], cost[i - 1, j], cost[i, j - 1])
    path_a = np.empty(n + m, dtype=np.int64)
    path_b = np.empty(n + m, dtype=np.int64)
    i, j, k = n, m, 0
    while i > 0 and j > 0:
        path_a[k], path_b[k] = i - 1, j - 1
        k += 1
        diagonal, up, left = cost[i - 1, j - 1], cost[i - 1, j], cost[i, j - 1]
        if diagonal <= up and diagonal <= left:
            i, j = i - 1, j - 1
        elif up <= left:
            i -= 1
        else:
            j -= 1
    return path_a[:k][::-1].copy(), path_b[:k][::-1].copy()


def dtw_path(a, b):
    """Dynamic time warping of two trajectories (Euclidean local distance).

    Parameters
    ----------
    a : array, shape (Ta, D)
    b : array, shape (Tb, D)

    Returns
    -------
    index_a, index_b : arrays of int, shape (L,)
        Matched samples, from (0, 0) to (Ta - 1, Tb - 1), each step advancing one or both.
    """
    a = as_trajectory("a", a)
    b = as_trajectory("b", b, a.shape[1])
    return _dtw_path(np.ascontiguousarray(a), np.ascontiguousarray(b))
