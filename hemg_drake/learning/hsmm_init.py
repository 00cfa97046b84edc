"""The HSMM's initial parameters: "kmeans", "time" and "polyline" segmentations.

Each initialisation labels every sample of every demonstration with a state; the states'
Gaussians, durations, transitions and start probabilities are then those of the labelled
runs, and the duration limits (``min_duration_std_``, ``max_duration_``) follow from the
runs' durations. :func:`initialise` does it for :class:`~hemg_drake.learning.hsmm.HSMM`
from its public parameters.
"""

import numpy as np
from scipy.cluster.vq import kmeans2

from hemg_drake.learning.hsmm_em import normalise_rows
from hemg_drake.learning.sequences import position_count

# Default floor on sigma_i^D, as a fraction of the initial segments' mean duration.
DURATION_STD_FLOOR = 0.02


def polyline_segments(points, n_segments, *, max_points=300):
    """Cut a path into the pieces that lie closest to straight lines (Bellman 1961).

    Minimises, by dynamic programming, the sum over pieces of the squared distances of
    their points to the piece's own least-squares line (for a piece with scatter matrix S,
    the sum of the eigenvalues of S but the largest). Straight runs and holds cost nothing,
    corners a lot, so the cuts fall where the path turns. Paths longer than ``max_points``
    are cut on every k-th point (the DP is O(n_segments T^2)).

    Parameters
    ----------
    points : array, shape (T, P)
        T >= n_segments.
    n_segments : int

    Returns
    -------
    array of int, shape (n_segments + 1,)
        Boundaries: piece i is points[b[i] : b[i + 1]]; b[0] = 0, b[-1] = T, increasing.
    """
    points = np.asarray(points, dtype=float)
    n_points = len(points)
    if n_points < n_segments:
        raise ValueError(f"{n_points} points cannot make {n_segments} pieces")
    step = max(1, min(-(-n_points // max_points), n_points // n_segments))
    x = points[::step]
    count = len(x)
    # Scatter of x[a:b] for every a < b, from cumulative sums.
    first = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    second = np.concatenate(
        [np.zeros((1, x.shape[1], x.shape[1])), np.cumsum(x[:, :, None] * x[:, None, :], 0)]
    )
    a, b = np.triu_indices(count + 1, 1)
    total = first[b] - first[a]
    scatter = second[b] - second[a] - total[:, :, None] * total[:, None, :] / (b - a)[:, None, None]
    cost = np.full((count + 1, count + 1), np.inf)
    cost[a, b] = np.maximum(np.linalg.eigvalsh(scatter)[:, :-1].sum(axis=1), 0.0)
    # best[k, j]: least cost of x[:j] in k pieces; arg[k, j]: where its last piece starts.
    best = np.full(count + 1, np.inf)
    best[0] = 0.0
    arg = np.zeros((n_segments + 1, count + 1), dtype=int)
    for k in range(1, n_segments + 1):
        candidates = best[:, None] + cost
        arg[k] = np.argmin(candidates, axis=0)
        best = candidates[arg[k], np.arange(count + 1)]
    bounds = [count]
    for k in range(n_segments, 0, -1):
        bounds.append(arg[k, bounds[-1]])
    bounds = step * np.array(bounds[::-1])
    bounds[-1] = n_points
    return bounds


def initialise(model, demos, samples, scale):
    """Set ``model``'s fitted arrays to those of its initial segmentation (before EM).

    Parameters
    ----------
    model : HSMM
        Read: ``n_states``, ``init``, ``n_init``, ``n_position``, ``random_state``,
        ``min_duration_std``, ``max_duration`` and ``floor_covariances``.
    demos : list of arrays (T_c, D)
    samples : array, shape (sum T_c, D)
        The demos concatenated.
    scale : array, shape (D,)
        Per-dimension spread the covariance floor is relative to.
    """
    n = model.n_states
    if model.init != "time":
        p = position_count(samples.shape[1], model.n_position)
    if model.init == "time":
        labels = [np.minimum(np.arange(len(d)) * n // len(d), n - 1) for d in demos]
    elif model.init == "polyline":
        labels = [np.repeat(np.arange(n), np.diff(polyline_segments(d[:, :p], n))) for d in demos]
    else:
        # Cluster positions only: states are then regions of the GMR input
        # space (what eq. 14 weighs), and strokes that look alike in
        # velocity or stiffness do not share states.
        positions = samples[:, : max(p, 1)]
        labels = kmeans_labels(
            demos, positions / scale[: positions.shape[1]], n, model.n_init, model.random_state
        )
    flat = np.concatenate(labels)
    global_cov = np.cov(samples, rowvar=False, bias=True).reshape(samples.shape[1], -1)
    means = np.empty((n, samples.shape[1]))
    covariances = np.empty((n, samples.shape[1], samples.shape[1]))
    durations = [[] for _ in range(n)]
    transitions = np.zeros((n, n))
    starts = np.zeros(n)
    duration_means = np.empty(n)
    duration_stds = np.empty(n)
    for label in labels:
        change = np.flatnonzero(np.diff(label)) + 1
        bounds = np.concatenate([[0], change, [len(label)]])
        for begin, end in zip(bounds[:-1], bounds[1:]):
            durations[label[begin]].append(end - begin)
        np.add.at(transitions, (label[change - 1], label[change]), 1.0)
        starts[label[0]] += 1.0
    for i in range(n):
        members = samples[flat == i]
        if len(members) > 1:
            means[i] = members.mean(axis=0)
            covariances[i] = np.cov(members, rowvar=False, bias=True)
        else:  # an empty cluster: a random sample, the data's spread
            pick = np.random.default_rng(model.random_state + i).integers(len(samples))
            means[i] = samples[pick]
            covariances[i] = global_cov
        d = np.array(durations[i] or [np.mean([len(x) for x in demos]) / n], dtype=float)
        duration_means[i] = d.mean()
        duration_stds[i] = d.std()
    model.means_ = means
    model.duration_means_ = duration_means
    (model.min_duration_std_, model.duration_stds_, model.max_duration_) = duration_limits(
        duration_means, duration_stds, demos, model.min_duration_std, model.max_duration
    )
    model.covariances_ = model.floor_covariances(covariances, scale)
    if model.init == "kmeans":
        # k-means runs flicker; a small pseudo-count keeps every order reachable for EM.
        transitions += 0.1 / max(n - 1, 1)
        starts += 0.1
    np.fill_diagonal(transitions, 0.0)
    model.transmat_ = normalise_rows(transitions, np.zeros((n, n)))
    model.startprob_ = starts / starts.sum()
    model.occupancy_ = np.bincount(flat, minlength=n) / len(flat)


def duration_limits(means, stds, demos, min_duration_std=None, max_duration=None):
    """The duration floor, floored spreads and d_max of an initial segmentation.

    Parameters
    ----------
    means, stds : arrays, shape (N,)
        Each state's mean and spread of run durations, in steps.
    demos : list of arrays
    min_duration_std, max_duration : optional
        The HSMM's parameters (None: from the durations).

    Returns
    -------
    min_duration_std_ : float
        Given, or 2 % of the mean duration, at least 1 step.
    duration_stds : array, shape (N,)
        ``stds`` floored at it.
    max_duration_ : int
        Given, or room for EM to lengthen any state: its mean plus 4 spreads, the spread at
        least a quarter of the mean, capped at the longest demonstration.
    """
    if min_duration_std is None:
        floor = max(1.0, DURATION_STD_FLOOR * float(np.mean(means)))
    else:
        floor = float(min_duration_std)
    stds = np.maximum(stds, floor)
    if max_duration is not None:
        return floor, stds, int(max_duration)
    spread = np.maximum(stds, 0.25 * means)
    estimate = int(np.ceil(np.max(means + 4.0 * spread)))
    return floor, stds, max(1, min(estimate, max(len(demo) for demo in demos)))


def kmeans_labels(demos, standardised, n_states, n_init, random_state):
    """Each demo's k-means++ labels of its rows of ``standardised`` (best of ``n_init``)."""
    rng = np.random.default_rng(random_state)
    best, best_inertia = None, np.inf
    for _ in range(n_init):
        centroids, label = kmeans2(
            standardised, n_states, iter=30, minit="++", missing="warn", seed=rng
        )
        inertia = np.sum((standardised - centroids[label]) ** 2)
        if inertia < best_inertia:
            best, best_inertia = label, inertia
    return np.split(best, np.cumsum([len(d) for d in demos])[:-1])
