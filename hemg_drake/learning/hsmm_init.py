"""The HSMM's initial parameters: "kmeans", "time" and "polyline" segmentations.

Each initialisation labels every sample of every demonstration with a state; the states'
Gaussians, durations, transitions and start probabilities are then those of the labelled
runs, and the duration limits (``min_duration_std_``, ``max_duration_``) follow from the
runs' durations. :class:`InitialisationMixin` holds the methods of
:class:`~hemg_drake.learning.hsmm.HSMM` that do it.
"""

import numpy as np
from scipy.cluster.vq import kmeans2

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


class InitialisationMixin:
    """The initial parameters of :class:`~hemg_drake.learning.hsmm.HSMM` (before EM)."""

    def _initialise(self, demos, samples, scale):
        n = self.n_states
        if self.init == "time":
            labels = [np.minimum(np.arange(len(d)) * n // len(d), n - 1) for d in demos]
        elif self.init == "polyline":
            p = self._n_position(samples.shape[1])
            labels = [
                np.repeat(np.arange(n), np.diff(polyline_segments(d[:, :p], n))) for d in demos
            ]
        else:
            # Cluster positions only: states are then regions of the GMR input
            # space (what eq. 14 weighs), and strokes that look alike in
            # velocity or stiffness do not share states.
            positions = samples[:, : max(self._n_position(samples.shape[1]), 1)]
            labels = self._kmeans_labels(demos, positions / scale[: positions.shape[1]])
        flat = np.concatenate(labels)
        global_cov = np.cov(samples, rowvar=False, bias=True).reshape(samples.shape[1], -1)
        self.means_ = np.empty((n, samples.shape[1]))
        self.covariances_ = np.empty((n, samples.shape[1], samples.shape[1]))
        durations = [[] for _ in range(n)]
        transitions = np.zeros((n, n))
        starts = np.zeros(n)
        self.duration_means_ = np.empty(n)
        self.duration_stds_ = np.empty(n)
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
                self.means_[i] = members.mean(axis=0)
                self.covariances_[i] = np.cov(members, rowvar=False, bias=True)
            else:  # an empty cluster: a random sample, the data's spread
                pick = np.random.default_rng(self.seed + i).integers(len(samples))
                self.means_[i] = samples[pick]
                self.covariances_[i] = global_cov
            d = np.array(durations[i] or [np.mean([len(x) for x in demos]) / n], dtype=float)
            self.duration_means_[i] = d.mean()
            self.duration_stds_[i] = d.std()
        self._set_duration_limits(demos)
        self.covariances_ = self._floor_covariances(self.covariances_, scale)
        if self.init == "kmeans":
            # k-means runs flicker; a small pseudo-count keeps every order reachable for EM.
            transitions += 0.1 / max(n - 1, 1)
            starts += 0.1
        np.fill_diagonal(transitions, 0.0)
        self.transmat_ = self._normalise_rows(transitions, np.zeros((n, n)))
        self.startprob_ = starts / starts.sum()
        self.occupancy_ = np.bincount(flat, minlength=n) / len(flat)

    def _set_duration_limits(self, demos):
        """min_duration_std_ and max_duration_ from the initial segmentation's durations."""
        means, stds = self.duration_means_, self.duration_stds_
        if self.min_duration_std is None:
            self.min_duration_std_ = max(1.0, DURATION_STD_FLOOR * float(np.mean(means)))
        else:
            self.min_duration_std_ = float(self.min_duration_std)
        self.duration_stds_ = np.maximum(stds, self.min_duration_std_)
        if self.max_duration is not None:
            self.max_duration_ = int(self.max_duration)
            return
        # Room for EM to lengthen any state: its mean plus 4 spreads, the spread at least a
        # quarter of the mean (so at least twice the longest initial segment).
        spread = np.maximum(self.duration_stds_, 0.25 * means)
        estimate = int(np.ceil(np.max(means + 4.0 * spread)))
        self.max_duration_ = max(1, min(estimate, max(len(demo) for demo in demos)))

    def _kmeans_labels(self, demos, standardised):
        rng = np.random.default_rng(self.seed)
        best, best_inertia = None, np.inf
        for _ in range(self.n_init):
            centroids, label = kmeans2(
                standardised, self.n_states, iter=30, minit="++", missing="warn", seed=rng
            )
            inertia = np.sum((standardised - centroids[label]) ** 2)
            if inertia < best_inertia:
                best, best_inertia = label, inertia
        return np.split(best, np.cumsum([len(d) for d in demos])[:-1])
