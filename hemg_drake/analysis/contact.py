"""Pen contact from a logged run: which samples touch (:func:`in_contact`) and the strokes
drawn while they did (:func:`ink_strokes`), from the pen tip P and its contact force sampled
together (the demonstration's logger records ``p_WE`` and ``f_WE`` every 0.01 s; in the
drawing scene the tool point E is the pen's tip)::

    touching = in_contact(f_WP)                           # |f| above a threshold
    strokes = ink_strokes(times, p_WP, touching)          # list of (k, 3) polylines

Analysis of logs (below :mod:`hemg_drake.viz`, which draws the ink into a replay with
:func:`hemg_drake.viz.ink.add_ink_to_recording`).
"""

import numpy as np

# A contact force above this (N) leaves ink: well above the solver's numerical noise, well
# below a pen's writing force (about 1-5 N).
CONTACT_THRESHOLD = 0.05


def in_contact(f_WP, threshold=CONTACT_THRESHOLD):
    """Whether each sample's contact force exceeds ``threshold`` (N).

    Parameters
    ----------
    f_WP : array, shape (n, 3), N.

    Returns
    -------
    array of bool, shape (n,).
    """
    f_WP = np.asarray(f_WP, dtype=float)
    if f_WP.ndim != 2 or f_WP.shape[1] != 3:
        raise ValueError(f"f_WP must have shape (n, 3), got {f_WP.shape}")
    if not np.all(np.isfinite(f_WP)):
        raise ValueError("f_WP contains NaN or inf")
    if not (np.isfinite(threshold) and threshold >= 0):
        raise ValueError(f"threshold must be finite and >= 0, got {threshold}")
    return np.linalg.norm(f_WP, axis=1) > threshold


def checked_trace(times, p_WP, touching):
    """``(times, p_WP, touching)`` as arrays, checked: one finite point and one bool per
    strictly increasing time; ValueError naming the problem."""
    times = np.asarray(times, dtype=float)
    p_WP = np.asarray(p_WP, dtype=float)
    touching = np.asarray(touching)
    n = times.shape[0] if times.ndim == 1 else -1
    if n < 0:
        raise ValueError(f"times must have shape (n,), got {times.shape}")
    if p_WP.shape != (n, 3):
        raise ValueError(f"p_WP must have shape ({n}, 3) (one point per time), got {p_WP.shape}")
    if touching.shape != (n,) or touching.dtype != bool:
        raise ValueError(
            f"in_contact must be {n} booleans (one per time), got {touching.dtype} "
            f"of shape {touching.shape}"
        )
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(p_WP))):
        raise ValueError("times and p_WP must be finite")
    if np.any(np.diff(times) <= 0):
        raise ValueError("times must be strictly increasing")
    return times, p_WP, touching


def contact_runs(touching, min_points):
    """(start, stop) index ranges of the runs of True at least ``min_points`` long."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], touching.astype(int), [0]])))
    return [(a, b) for a, b in zip(edges[0::2], edges[1::2]) if b - a >= min_points]


def ink_strokes(times, p_WP, in_contact, *, min_points=2):
    """Split a pen-tip trace into the strokes drawn while it touched the paper.

    Parameters
    ----------
    times : array, shape (n,), s, strictly increasing.
    p_WP : array, shape (n, 3), pen tip positions in W (m).
    in_contact : array of bool, shape (n,).
    min_points : int, shortest stroke kept (a single touching sample leaves no line).

    Returns
    -------
    list of arrays, shape (k, 3): the consecutive touching samples, in time order.
    """
    _, p_WP, touching = checked_trace(times, p_WP, in_contact)
    if int(min_points) < 1:
        raise ValueError(f"min_points must be >= 1, got {min_points}")
    return [p_WP[a:b].copy() for a, b in contact_runs(touching, int(min_points))]
