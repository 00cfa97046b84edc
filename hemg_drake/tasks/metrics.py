"""How well a reproduction does its task: the paper's Table II and the task checks.

**Table II, three ways.** The paper does not say how its RMSE aligns the reproduction with
the demonstrations (against their mean or each one, resampled or warped, per axis or as a
Euclidean norm), so three figures are kept apart:

- *time-normalised* (:func:`time_normalised_rmse`, the lead figure): every signal resampled
  over its own duration to a common length, against the mean demonstration; it counts
  errors in timing as errors, as a sample-by-sample comparison does;
- *spatial*, after DTW (:func:`aligned_rmse`): the distance to the demonstrated path,
  blind to timing (a reproduction that stalls scores like one that does not);
- *timing* (:func:`timing_error`): how far DTW had to shift time, RMS in seconds.

The demonstrations' own leave-one-out figures (:func:`leave_one_out`: each demonstration
against the others' mean) are the floor a human run reaches.

**Alignment after DTW.** The reference is the *mean demonstration after DTW*: every demonstration is aligned to the
first one by dynamic time warping on the positions, the samples matched to each sample of
the first are averaged, then over the demonstrations (:func:`mean_demonstration`). The
reproduction is aligned to that mean by DTW on the positions, and both RMSEs are taken over
the pairs of the warping path (:func:`aligned_rmse`)::

    RMSE_x    = sqrt( mean over pairs (k, l) of |x*_k - xbar_l|^2 )      (m)
    RMSE_xdot = sqrt( mean over pairs (k, l) of |xdot*_k - xbardot_l|^2 )  (m/s)

with |.| the Euclidean norm over the three axes. :func:`time_normalised_rmse` gives the
plain alternative (every signal resampled to a common length over its own duration), kept
for comparison. The velocities follow the position path: DTW never aligns on them.

**Tasks.** Drawing: the strokes are cut from a log by
:func:`hemg_drake.viz.ink.ink_strokes`; :func:`stroke_errors` compares a stroke with the
demonstrations' mean stroke after resampling both by arc length: its shape (both centred)
and its placement (the centroids' distance). Forces: :func:`force_statistics`. Stiffness:
:func:`stiffness_correlation` (Pearson, along the same warping path).
"""

import numpy as np

# One DTW and one trajectory check: the learning layer's (its alignment uses them too).
from hemg_drake.learning.dtw import as_trajectory as _as_trajectory
from hemg_drake.learning.dtw import dtw_path

ALIGNMENT = (
    "DTW on position against the mean demonstration (each demonstration DTW-aligned to the "
    "first and averaged); RMSE of the Euclidean error over the warping path"
)


def mean_demonstration(demos, position_columns=slice(0, 3)):
    """The demonstrations averaged on the time axis of the first, after DTW.

    Parameters
    ----------
    demos : list of arrays, shape (T_c, D)
        Columns ``position_columns`` are aligned on; all columns are averaged.
    position_columns : slice or sequence of int

    Returns
    -------
    array, shape (T_0, D)
    """
    demos = [_as_trajectory(f"demonstration {c}", demo) for c, demo in enumerate(demos, 1)]
    if not demos:
        raise ValueError("mean_demonstration needs at least one demonstration")
    reference = demos[0]
    total = np.zeros_like(reference)
    for c, demo in enumerate(demos):
        if demo.shape[1] != reference.shape[1]:
            raise ValueError(
                f"demonstration {c + 1} has {demo.shape[1]} columns, demonstration 1 has "
                f"{reference.shape[1]}"
            )
        index_ref, index_demo = dtw_path(reference[:, position_columns], demo[:, position_columns])
        # Average the samples matched to each reference sample (each is matched at least once).
        counts = np.bincount(index_ref, minlength=len(reference))[:, None]
        sums = np.zeros_like(reference)
        np.add.at(sums, index_ref, demo[index_demo])
        total += sums / counts
    return total / len(demos)


def aligned_rmse(
    reproduced, reference, position_columns=slice(0, 3), velocity_columns=slice(3, 6)
):
    """Table II's RMSEs of a reproduction against a reference, along their DTW path.

    Parameters
    ----------
    reproduced, reference : arrays, shape (T, D) and (T_ref, D)
        Same columns, e.g. [x, xdot, k].

    Returns
    -------
    dict
        ``position_rmse`` (m), ``velocity_rmse`` (m/s), and ``path``: the matched indices.
    """
    reproduced = _as_trajectory("reproduced", reproduced)
    reference = _as_trajectory("reference", reference, reproduced.shape[1])
    path = dtw_path(reproduced[:, position_columns], reference[:, position_columns])
    matched, to = reproduced[path[0]], reference[path[1]]
    return {
        "position_rmse": _rmse(matched[:, position_columns], to[:, position_columns]),
        "velocity_rmse": _rmse(matched[:, velocity_columns], to[:, velocity_columns]),
        "path": path,
    }


def _rmse(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def _check_n_samples(n_samples):
    if not isinstance(n_samples, (int, np.integer)) or n_samples < 2:
        raise ValueError(f"n_samples must be an integer >= 2, got {n_samples!r}")


def time_normalise(trajectory, n_samples):
    """Resample a trajectory to ``n_samples`` at equal fractions of its duration (linear).

    Parameters
    ----------
    trajectory : array, shape (T, D)
    n_samples : int >= 2

    Returns
    -------
    array, shape (n_samples, D)
    """
    trajectory = _as_trajectory("trajectory", trajectory)
    _check_n_samples(n_samples)
    old = np.linspace(0.0, 1.0, len(trajectory))
    new = np.linspace(0.0, 1.0, n_samples)
    return np.column_stack([np.interp(new, old, column) for column in trajectory.T])


def time_normalised_rmse(
    reproduced, demos, position_columns=slice(0, 3), velocity_columns=slice(3, 6)
):
    """RMSEs against the mean of the demonstrations, all resampled to the mean length.

    Returns
    -------
    dict with ``position_rmse`` (m) and ``velocity_rmse`` (m/s).
    """
    demos = [_as_trajectory(f"demonstration {c}", demo) for c, demo in enumerate(demos, 1)]
    if not demos:
        raise ValueError("time_normalised_rmse needs at least one demonstration")
    n_samples = int(round(np.mean([len(demo) for demo in demos])))
    mean = np.mean([time_normalise(demo, n_samples) for demo in demos], axis=0)
    reproduced = time_normalise(reproduced, n_samples)
    return {
        "position_rmse": _rmse(reproduced[:, position_columns], mean[:, position_columns]),
        "velocity_rmse": _rmse(reproduced[:, velocity_columns], mean[:, velocity_columns]),
    }


def timing_error(path, dt):
    """RMS time shift (s) along a DTW path between two signals sampled every ``dt`` s.

    Zero for two signals with the same timing; a reproduction that stalls for n samples
    and catches up scores about n dt / 2.
    """
    index_a, index_b = (np.asarray(index, dtype=float) for index in path)
    if index_a.shape != index_b.shape or index_a.ndim != 1 or not len(index_a):
        raise ValueError("path must be two index arrays of one length (dtw_path's result)")
    return float(dt * np.sqrt(np.mean((index_a - index_b) ** 2)))


def leave_one_out(demos, dt, position_columns=slice(0, 3), velocity_columns=slice(3, 6)):
    """Each demonstration measured as a reproduction against the mean of the others.

    Parameters
    ----------
    demos : list of arrays, shape (T_c, D), C >= 2.
    dt : float, sample period (s).

    Returns
    -------
    list of dict, one per demonstration: ``position_rmse``, ``velocity_rmse``
    (time-normalised), ``spatial_position_rmse`` and ``spatial_velocity_rmse`` (after DTW)
    and ``timing_error_s``.
    """
    if len(demos) < 2:
        raise ValueError(f"leave_one_out needs at least 2 demonstrations, got {len(demos)}")
    results = []
    for c, demo in enumerate(demos):
        others = [other for k, other in enumerate(demos) if k != c]
        plain = time_normalised_rmse(demo, others, position_columns, velocity_columns)
        aligned = aligned_rmse(demo, mean_demonstration(others, position_columns),
                               position_columns, velocity_columns)  # fmt: skip
        results.append({
            "position_rmse": plain["position_rmse"],
            "velocity_rmse": plain["velocity_rmse"],
            "spatial_position_rmse": aligned["position_rmse"],
            "spatial_velocity_rmse": aligned["velocity_rmse"],
            "timing_error_s": timing_error(aligned["path"], dt),
        })  # fmt: skip
    return results


def stiffness_correlation(k_reproduced, k_reference, path=None):
    """Pearson correlation of two stiffness profiles, along a warping path if given.

    Parameters
    ----------
    k_reproduced : array, shape (T,)
    k_reference : array, shape (T_ref,)
        Same length as ``k_reproduced`` unless ``path`` is given.
    path : (index_reproduced, index_reference), optional
        E.g. ``aligned_rmse(...)["path"]``.

    Returns
    -------
    float in [-1, 1], or None when either profile is constant (undefined).
    """
    k_reproduced = _as_trajectory("k_reproduced", k_reproduced, 1)[:, 0]
    k_reference = _as_trajectory("k_reference", k_reference, 1)[:, 0]
    if path is not None:
        k_reproduced, k_reference = k_reproduced[path[0]], k_reference[path[1]]
    elif len(k_reproduced) != len(k_reference):
        raise ValueError(
            f"k_reproduced and k_reference differ in length ({len(k_reproduced)}, "
            f"{len(k_reference)}); give the warping path"
        )
    if np.ptp(k_reproduced) == 0 or np.ptp(k_reference) == 0:
        return None
    return float(np.corrcoef(k_reproduced, k_reference)[0, 1])


def force_statistics(force):
    """Peak and mean of the norm of a force over time.

    Parameters
    ----------
    force : array, shape (T, 3), N.

    Returns
    -------
    dict with ``peak`` and ``mean`` (N).
    """
    norm = np.linalg.norm(_as_trajectory("force", force, 3), axis=1)
    return {"peak": float(norm.max()), "mean": float(norm.mean())}


def resample_by_arc_length(points, n_samples=50):
    """``n_samples`` points equally spaced along a polyline (the first and last kept).

    Parameters
    ----------
    points : array, shape (T, D), T >= 2, not all equal.
    n_samples : int >= 2

    Returns
    -------
    array, shape (n_samples, D)
    """
    points = _as_trajectory("points", points)
    _check_n_samples(n_samples)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    if arc[-1] == 0:
        raise ValueError("a stroke of zero length cannot be resampled by arc length")
    new = np.linspace(0.0, arc[-1], n_samples)
    return np.column_stack([np.interp(new, arc, column) for column in points.T])


def stroke_errors(stroke, demo_strokes, n_samples=50):
    """How a stroke differs from the mean of the demonstrations' same stroke: shape and place.

    Every stroke is resampled by arc length to ``n_samples`` points; the mean stroke is
    their point-wise mean. The RMS distance between the stroke and the mean splits exactly
    into ``placement`` (the distance between their centroids) and ``shape`` (the RMS distance
    once both are centred): rms^2 = shape^2 + placement^2.

    Parameters
    ----------
    stroke : array, shape (T, D), positions (e.g. x, y on the paper), m.
    demo_strokes : list of arrays, shape (T_c, D)

    Returns
    -------
    dict with ``shape``, ``placement`` and ``rms`` (m).
    """
    if not demo_strokes:
        raise ValueError("stroke_errors needs at least one demonstrated stroke")
    mean = np.mean([resample_by_arc_length(s, n_samples) for s in demo_strokes], axis=0)
    points = resample_by_arc_length(stroke, n_samples)
    if points.shape[1] != mean.shape[1]:
        raise ValueError(
            f"stroke has {points.shape[1]} columns, the demonstrated strokes {mean.shape[1]}"
        )
    offset = points.mean(axis=0) - mean.mean(axis=0)
    return {
        "shape": _rmse(points - offset, mean),
        "placement": float(np.linalg.norm(offset)),
        "rms": _rmse(points, mean),
    }
