"""Hidden semi-Markov model with explicit Gaussian durations, trained by EM (eqs. 4-11)."""

import inspect
import json
import warnings
from pathlib import Path

import numpy as np
from scipy.cluster.vq import kmeans2

from hemg_drake.fileio import load_npz, save_npz_atomic
from hemg_drake.learning import _kernels
from hemg_drake.learning.gmr import gaussian_log_pdf
from hemg_drake.learning.forward import ResidualForward

# Version 2 added data_range_ (reproduction clips the stiffness to it).
FORMAT_VERSION = 2
INITS = ("kmeans", "time", "polyline")
# Default floor on sigma_i^D, as a fraction of the initial segments' mean duration.
DURATION_STD_FLOOR = 0.02
PARAMETERS = (
    "n_states", "max_duration", "reg_covar", "min_duration_std", "n_iter", "tol", "init",
    "n_init", "n_position", "seed",
)  # fmt: skip
_FITTED = (
    "startprob_", "transmat_", "means_", "covariances_",
    "duration_means_", "duration_stds_", "occupancy_", "data_range_",
)  # fmt: skip


def _log(x):
    with np.errstate(divide="ignore"):
        return np.log(x)


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


def check_demos(demos, n_dims=None):
    """Validate demonstrations; return them as a list of float arrays (T_c, D).

    Raises ``ValueError`` naming the demonstration at fault for a wrong shape,
    NaN/inf, a dimension other than ``n_dims`` or the others' dimension.
    """
    if isinstance(demos, np.ndarray) and demos.ndim == 2:
        demos = [demos]
    demos = [np.asarray(demo, dtype=float) for demo in demos]
    if not demos:
        raise ValueError("demos is empty: give at least one array of shape (T, D)")
    for c, demo in enumerate(demos):
        if demo.ndim != 2 or demo.shape[0] < 1 or demo.shape[1] < 1:
            raise ValueError(f"demonstration {c + 1} must have shape (T, D), got {demo.shape}")
        if not np.all(np.isfinite(demo)):
            raise ValueError(f"demonstration {c + 1} contains NaN or inf")
        expected = demos[0].shape[1] if n_dims is None else n_dims
        if demo.shape[1] != expected:
            where = "the model's" if n_dims is not None else "demo 0's"
            raise ValueError(
                f"demonstration {c + 1} has D = {demo.shape[1]} dimensions, {where} is D = {expected}"
            )
    return demos


def split_sequences(X, lengths=None):
    """hmmlearn's form to a list: X of shape (sum(lengths), D) cut into ``lengths`` rows.

    Parameters
    ----------
    X : array, shape (n_samples, D), or list of arrays (T_c, D)
        With ``lengths=None`` a 2-D array is one sequence and a list is taken as it is.
    lengths : sequence of int, optional
        Sequence lengths, summing to ``len(X)``.

    Returns
    -------
    list of arrays (T_c, D)
    """
    if lengths is None:
        return [X] if isinstance(X, np.ndarray) and X.ndim == 2 else list(X)
    X = np.asarray(X, dtype=float)
    lengths = np.asarray(lengths)
    if X.ndim != 2:
        raise ValueError(f"X must have shape (n_samples, D) with lengths, got {X.shape}")
    if (
        lengths.ndim != 1 or lengths.size == 0 or not np.issubdtype(lengths.dtype, np.integer)
        or np.any(lengths < 1) or lengths.sum() != len(X)
    ):  # fmt: skip
        raise ValueError(
            f"lengths must be integers >= 1 summing to len(X) = {len(X)}, got {lengths.tolist()}"
        )
    return np.split(X, np.cumsum(lengths)[:-1])


class HSMM:
    """Explicit-duration hidden semi-Markov model with full-covariance Gaussian states.

    lambda = {pi, A, {mu_i, Sigma_i}, {mu_i^D, sigma_i^D}} (eq. 4): no
    self-transitions (the diagonal of A is zero), Gaussian durations in steps
    up to ``max_duration``. EM (eqs. 5-6) runs forward-backward in log space,
    O(T N w) per demonstration for duration supports of w steps, so sequences of any
    length are safe.

    Modelling choices: the duration density is the Gaussian evaluated at
    d = 1 .. d_max, not renormalised over that range, so that the M-step
    (weighted moments) is exact and the log-likelihood never decreases; it is zero
    beyond 10 sigma_i^D of the mean (below e^-50 of its peak), so the recursions skip
    those durations. The duration standard deviation is floored at ``min_duration_std``
    steps and covariance eigenvalues (in data-standardised units) at ``reg_covar``, both
    exact constrained M-steps. A sequence must end with a complete segment.

    The estimator API follows hmmlearn and scikit-learn: ``fit(X, lengths)``,
    ``score``, ``decode`` (segmental Viterbi), ``sample``, ``bic`` / ``aic``,
    ``get_params`` / ``set_params`` (``sklearn.base.clone`` works).

    Parameters
    ----------
    n_states : int
        N >= 1.
    max_duration : int, optional
        d_max in steps. Default: from the initial segmentation's durations (mean mu_i
        and spread s_i of each state's runs), max_i (mu_i + 4 max(s_i, mu_i / 4)), i.e.
        at least twice the longest mean, capped at the longest demonstration. The cost
        is set by the duration supports (10 sigma_i^D each side), not by d_max.
    reg_covar : float
        Floor on covariance eigenvalues, relative to each dimension's variance
        over all the data (so the floor does not depend on units). The default 1e-2
        has the best held-out log-likelihood on real handwriting: leave one
        demonstration out over the 30 LASA shapes (D = 4, N = 10), 17.42 nats per
        sample (init "kmeans"; 1e-2 or 3e-2 best on 28 of 30 shapes) against 16.04 at
        1e-3, 12.80 at 1e-6 and 16.86 at 1e-1 (init "time": 17.38, 16.94, 16.87, 16.71).
        Synthetic demonstrations that differ only by white noise (tests/learning) prefer
        the smallest floors (18.07 at 1e-6, 14.16 at 1e-2): lower it for such data.
        (``benchmarks/bench_lasa.py --held-out --full``; docs/learning.md.)
        A dimension that does not vary (spread below 1e-12 of the data's largest
        magnitude: a held coordinate, its gradient) is floored at reg_covar in its own
        units instead.
    min_duration_std : float, optional
        Floor on sigma_i^D, in steps. Default: 2 % of the initial segments' mean
        duration, at least 1 step (1.1 steps at 55-step segments, 11 at 555), so the floor
        scales with the sampling rate (``min_duration_std_``).
    n_iter : int
        Maximum number of EM iterations.
    tol : float
        Stop when an iteration gains less than ``tol`` nats per sample (the total
        log-likelihood gain divided by the number of samples: the same rule for any
        units and data size). The default 1e-3 stops within 0.01 nats per sample of the
        converged likelihood on LASA (12 iterations against 32 with 1e-4, 180 with 0).
    init : {"kmeans", "time", "polyline"}
        "kmeans": seeded k-means++ on the positions x of all samples (best of
        ``n_init`` runs), durations and transitions from its runs; "time": each demonstration
        cut into N equal segments, a left-to-right model (zeros in A stay
        zero under EM); "polyline": left to right too, each demonstration cut into the N
        pieces whose positions lie closest to straight lines (:func:`polyline_segments`),
        so that states start where the path turns, not at equal times.
    n_init : int
        k-means restarts.
    n_position : int, optional
        Layout of xi = [x (P), xdot (P), k (rest)]; default P = D // 2, so
        D = 7 gives [x(3), xdot(3), k(1)], D = 6 no stiffness, D = 4 planar.
    seed : int
        Seed of every random draw.

    Attributes
    ----------
    startprob_ : array, shape (N,)
    transmat_ : array, shape (N, N)
        a_ij at [i, j]; zero diagonal; rows of states never left may be zero.
    means_ : array, shape (N, D)
    covariances_ : array, shape (N, D, D)
    duration_means_, duration_stds_ : arrays, shape (N,)
        In steps.
    occupancy_ : array, shape (N,)
        Fraction of training samples in each state (the prior of eq. 14).
    data_range_ : array, shape (2, D)
        Smallest and largest value of each dimension in the training data (reproduction
        keeps k* inside it).
    max_duration_ : int
    min_duration_std_ : float
        The floor used in the last fit (not saved).
    log_likelihood_history_ : list of float
        Total log-likelihood of all demonstrations before each M-step.
    n_iter_ : int
    converged_ : bool
    """

    def __init__(
        self,
        n_states,
        *,
        max_duration=None,
        reg_covar=1e-2,
        min_duration_std=None,
        n_iter=100,
        tol=1e-3,
        init="kmeans",
        n_init=5,
        n_position=None,
        seed=0,
    ):
        self.n_states = n_states
        self.max_duration = max_duration
        self.reg_covar = reg_covar
        self.min_duration_std = min_duration_std
        self.n_iter = n_iter
        self.tol = tol
        self.init = init
        self.n_init = n_init
        self.n_position = n_position
        self.seed = seed
        self._check_parameters()

    def get_params(self, deep=True):
        """The constructor's parameters by name (scikit-learn's estimator protocol).

        Parameters
        ----------
        deep : bool
            Ignored (no parameter is an estimator); kept for scikit-learn.

        Returns
        -------
        dict
        """
        return {name: getattr(self, name) for name in PARAMETERS}

    def set_params(self, **params):
        """Set constructor parameters by name; checked as in the constructor. Returns self."""
        unknown = sorted(set(params) - set(PARAMETERS))
        if unknown:
            raise ValueError(f"unknown HSMM parameter(s) {unknown}; valid: {list(PARAMETERS)}")
        previous = self.get_params()
        for name, value in params.items():
            setattr(self, name, value)
        try:
            self._check_parameters()
        except ValueError:
            for name, value in previous.items():
                setattr(self, name, value)
            raise
        return self

    def __repr__(self):
        changed = {
            name: value for name, value in self.get_params().items()
            if name == "n_states" or value != _DEFAULTS[name]
        }  # fmt: skip
        return "HSMM(" + ", ".join(f"{name}={value!r}" for name, value in changed.items()) + ")"

    def _check_parameters(self):
        def integer(value):
            return isinstance(value, (int, np.integer)) and not isinstance(value, bool)

        if not integer(self.n_states) or self.n_states < 1:
            raise ValueError(f"n_states must be an integer >= 1, got {self.n_states!r}")
        if self.max_duration is not None and (
            not integer(self.max_duration) or self.max_duration < 1
        ):
            raise ValueError(f"max_duration must be an integer >= 1, got {self.max_duration!r}")
        if not self.reg_covar > 0:
            raise ValueError(f"reg_covar must be > 0, got {self.reg_covar!r}")
        if self.min_duration_std is not None and not self.min_duration_std > 0:
            raise ValueError(f"min_duration_std must be > 0, got {self.min_duration_std!r}")
        if not integer(self.n_iter) or self.n_iter < 1:
            raise ValueError(f"n_iter must be an integer >= 1, got {self.n_iter!r}")
        if not self.tol >= 0:
            raise ValueError(f"tol must be >= 0, got {self.tol!r}")
        if self.init not in INITS:
            raise ValueError(f"init must be one of {INITS}, got {self.init!r}")
        if not integer(self.n_init) or self.n_init < 1:
            raise ValueError(f"n_init must be an integer >= 1, got {self.n_init!r}")
        if self.n_position is not None and (not integer(self.n_position) or self.n_position < 1):
            raise ValueError(f"n_position must be an integer >= 1, got {self.n_position!r}")

    # ------------------------------------------------------------------ layout
    @property
    def n_dims_(self):
        self._check_fitted()
        return self.means_.shape[1]

    @property
    def position_dims_(self):
        """Indices of x, the input of GMR."""
        return np.arange(self._n_position())

    @property
    def velocity_dims_(self):
        """Indices of xdot, integrated by eq. 18."""
        p = self._n_position()
        return np.arange(p, 2 * p)

    @property
    def stiffness_dims_(self):
        """Indices of k (possibly empty)."""
        return np.arange(2 * self._n_position(), self.n_dims_)

    def _n_position(self, n_dims=None):
        n_dims = self.n_dims_ if n_dims is None else n_dims
        p = n_dims // 2 if self.n_position is None else self.n_position
        if 2 * p > n_dims:
            raise ValueError(
                f"n_position = {p} needs D >= {2 * p} (x and xdot), the model has D = {n_dims}"
            )
        return p

    # -------------------------------------------------------------------- fit
    def fit(self, X, lengths=None):
        """Estimate the model from demonstrations by EM.

        Parameters
        ----------
        X : list of arrays, shape (T_c, D), or array, shape (n_samples, D)
            C demonstrations of possibly different lengths T_c >= n_states; or, as in
            hmmlearn, their concatenation with ``lengths`` (a 2-D array without ``lengths``
            is one demonstration).
        lengths : sequence of int, optional
            T_c of each demonstration in ``X``.

        Returns
        -------
        self
        """
        self._check_parameters()
        demos = check_demos(split_sequences(X, lengths))
        for c, demo in enumerate(demos):
            if len(demo) < self.n_states:
                raise ValueError(
                    f"demonstration {c + 1} has {len(demo)} steps, fewer than the N = {self.n_states} states"
                )
        samples = np.concatenate(demos)
        self.data_range_ = np.stack([samples.min(axis=0), samples.max(axis=0)])
        scale = samples.std(axis=0)
        # A constant dimension's std is 0 or rounding noise (a held coordinate, the gradient
        # of one): a floor relative to that is no floor, so a dimension whose spread is
        # below 1e-12 of the data's largest magnitude is floored in its own units.
        scale[scale <= 1e-12 * np.abs(samples).max()] = 1.0
        self._initialise(demos, samples, scale)
        self.log_likelihood_history_ = []
        self.converged_ = False
        n_samples = len(samples)
        outer = (samples[:, :, None] * samples[:, None, :]).reshape(n_samples, -1)
        for self.n_iter_ in range(1, self.n_iter + 1):
            stats = self._expectation(demos, outer)
            if not np.isfinite(stats["log_likelihood"]):
                raise ValueError(
                    "the demos cannot be segmented into at most "
                    f"max_duration = {self.max_duration_} steps per state visit; "
                    "raise max_duration or n_states"
                )
            history = self.log_likelihood_history_
            history.append(stats["log_likelihood"])
            self._maximisation(stats, scale)
            if len(history) > 1 and history[-1] - history[-2] < self.tol * n_samples:
                self.converged_ = True
                break
        return self

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

    @staticmethod
    def _normalise_rows(counts, previous):
        """Rows of counts normalised; a row with no counts keeps its previous value."""
        totals = counts.sum(axis=1, keepdims=True)
        return np.where(totals > 0, counts / np.where(totals > 0, totals, 1.0), previous)

    def _floor_covariances(self, covariances, scale):
        # Eigenvalue floor in standardised units: the exact maximiser of the
        # Gaussian likelihood under Sigma >= reg_covar (per-dimension variance).
        standardised = covariances / np.outer(scale, scale)
        values, vectors = np.linalg.eigh(standardised)
        values = np.maximum(values, self.reg_covar)
        floored = (vectors * values[:, None, :]) @ np.swapaxes(vectors, 1, 2)
        floored = 0.5 * (floored + np.swapaxes(floored, 1, 2))
        return floored * np.outer(scale, scale)

    def _log_durations(self):
        """log p_i(d) for d = 1 .. d_max, shape (N, d_max); -inf beyond the support.

        The support is |d - mu_i^D| <= 10 sigma_i^D (p below e^-50 of its peak is taken as
        zero), so the recursions cost O(T N sigma) rather than O(T N d_max).
        """
        d = np.arange(1, self.max_duration_ + 1)
        z = (d[None, :] - self.duration_means_[:, None]) / self.duration_stds_[:, None]
        log_p = -0.5 * z**2 - np.log(np.sqrt(2.0 * np.pi) * self.duration_stds_)[:, None]
        return np.where(0.5 * z**2 <= _kernels._NEGLIGIBLE, log_p, -np.inf)

    def _log_parameters(self):
        return _log(self.startprob_), _log(self.transmat_), self._log_durations()

    def _posteriors(self, log_emission, log_parameters):
        """Forward-backward on one demo's (T, N) emission log-likelihoods.

        Returns the log-likelihood and a dict of state posteriors ``gamma`` (T, N) and the
        expected ``starts``, ``transitions`` and ``durations`` counts (None if impossible).
        """
        log_startprob, log_transmat, log_duration = log_parameters
        log_alpha, log_alpha_in = _kernels.forward(
            log_emission, log_startprob, log_transmat, log_duration
        )
        log_likelihood = np.logaddexp.reduce(log_alpha[-1])
        if not np.isfinite(log_likelihood):
            return log_likelihood, None
        _, _, transitions, duration_counts, starts, ends = _kernels.backward(
            log_emission, log_transmat, log_duration, log_alpha, log_alpha_in, log_likelihood
        )
        return log_likelihood, {
            "gamma": _kernels.occupancy(starts, ends),
            "starts": starts[0],
            "transitions": transitions,
            "durations": duration_counts,
        }

    def _expectation(self, demos, outer=None):
        """E-step over all demos; ``outer``: their samples' x x^T as rows (T, D^2), if known.

        One compiled call runs every demonstration's forward-backward pass
        (:func:`_kernels.expectation`): per demonstration in Python, the calls and their
        bookkeeping cost about as much as the emissions on LASA-sized sets.
        """
        n = self.n_states
        samples = demos[0] if len(demos) == 1 else np.concatenate(demos)
        bounds = np.concatenate([[0], np.cumsum([len(d) for d in demos])])
        log_emission = gaussian_log_pdf(samples, self.means_, self.covariances_)
        log_likelihood, gamma, starts, transitions, durations = _kernels.expectation(
            log_emission, bounds, *self._log_parameters()
        )
        stats = {
            "log_likelihood": log_likelihood,
            "starts": starts,
            "transitions": transitions,
            "durations": durations,
        }
        if not np.isfinite(log_likelihood):
            return stats
        n_dims = samples.shape[1]
        if outer is None:
            outer = (samples[:, :, None] * samples[:, None, :]).reshape(len(samples), -1)
        stats["weight"] = gamma.sum(axis=0)
        stats["sum"] = gamma.T @ samples
        stats["outer"] = (gamma.T @ outer).reshape(n, n_dims, n_dims)  # one matrix product
        return stats

    def _maximisation(self, stats, scale):
        weight = stats["weight"]
        used = weight > 1e-10 * weight.sum()  # states with no mass keep their parameters
        means = stats["sum"][used] / weight[used, None]
        covariances = stats["outer"][used] / weight[used, None, None] - np.einsum(
            "nd,ne->nde", means, means
        )
        self.means_[used] = means
        self.covariances_[used] = self._floor_covariances(covariances, scale)
        self.startprob_ = stats["starts"] / stats["starts"].sum()
        self.transmat_ = self._normalise_rows(stats["transitions"], self.transmat_)
        counts = stats["durations"]
        total = counts.sum(axis=1)
        has = total > 0
        d = np.arange(1, self.max_duration_ + 1)
        mean = counts[has] @ d / total[has]
        variance = (counts[has] * (d[None, :] - mean[:, None]) ** 2).sum(axis=1) / total[has]
        self.duration_means_[has] = mean
        self.duration_stds_[has] = np.maximum(np.sqrt(variance), self.min_duration_std_)
        self.occupancy_ = weight / weight.sum()

    # -------------------------------------------------------------- inference
    def _check_fitted(self):
        if not all(hasattr(self, name) for name in _FITTED):
            raise ValueError("this HSMM is not fitted yet: call fit(demos) or HSMM.load(path)")

    def _check_demo(self, demo):
        self._check_fitted()
        return check_demos([demo], n_dims=self.means_.shape[1])[0]

    def _demo_posteriors(self, demo):
        """:meth:`_posteriors` of one demonstration (checked)."""
        return self._posteriors(self._log_emission(demo, True), self._log_parameters())

    def log_likelihood(self, demo):
        """log p(demo | lambda) of one ``demo`` of shape (T, D), as a float.

        The sequence ends with a complete segment; -inf if the model cannot produce it.
        """
        return float(self._demo_posteriors(demo)[0])

    def predict_states(self, demo):
        """Most likely state at each step (argmax of the smoothed posterior).

        Parameters
        ----------
        demo : array, shape (T, D)

        Returns
        -------
        array of int, shape (T,)
        """
        _, post = self._demo_posteriors(demo)
        if post is None:
            raise ValueError("the model cannot produce this demo (log-likelihood is -inf)")
        return np.argmax(post["gamma"], axis=1)

    def score(self, X, lengths=None):
        """Total log-likelihood of one or more sequences (hmmlearn's ``score``).

        Parameters
        ----------
        X : array, shape (n_samples, D), or list of arrays (T_c, D)
        lengths : sequence of int, optional
            As for :meth:`fit`.

        Returns
        -------
        float
            sum_c log p(sequence c | lambda) (-inf if one cannot be produced).
        """
        return float(sum(self.log_likelihood(demo) for demo in self._sequences(X, lengths)))

    def _sequences(self, X, lengths):
        self._check_fitted()
        return check_demos(split_sequences(X, lengths), n_dims=self.means_.shape[1])

    def decode(self, X, lengths=None):
        """Most likely state sequence, by segmental Viterbi (hmmlearn's ``decode``).

        The best segmentation (states and durations) jointly, not the per-step argmax of
        :meth:`predict_states`. With no self-transitions, each run of one state in the
        result is one segment: :func:`segments` gives (state, start, duration).

        Parameters
        ----------
        X : array, shape (n_samples, D), or list of arrays (T_c, D)
        lengths : sequence of int, optional
            As for :meth:`fit`.

        Returns
        -------
        log_probability : float
            sum over sequences of log p(xi, best segmentation).
        states : array of int, shape (n_samples,)
            All sequences' states, concatenated.

        Raises
        ------
        ValueError
            If a sequence cannot be produced by the model.
        """
        log_parameters = self._log_parameters()
        total, states = 0.0, []
        for c, demo in enumerate(self._sequences(X, lengths)):
            log_emission = gaussian_log_pdf(demo, self.means_, self.covariances_)
            log_probability, path = _kernels.viterbi(log_emission, *log_parameters)
            if not np.isfinite(log_probability):
                raise ValueError(f"the model cannot produce sequence {c} (probability 0)")
            total += log_probability
            states.append(path)
        return float(total), np.concatenate(states)

    def sample(self, n_samples, seed=0):
        """Draw one sequence from the model (hmmlearn's ``sample``).

        The first state from pi, each duration from p_i(d) normalised over its support,
        observations from N(mu_i, Sigma_i), the next state from row i of A (a state whose
        row is zero, never left in training, continues). The last segment is cut at
        ``n_samples``.

        Parameters
        ----------
        n_samples : int >= 1
        seed : int or numpy.random.Generator

        Returns
        -------
        X : array, shape (n_samples, D)
        states : array of int, shape (n_samples,)
        """
        self._check_fitted()
        if not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
            raise ValueError(f"n_samples must be an integer >= 1, got {n_samples!r}")
        rng = np.random.default_rng(seed)
        durations = np.exp(self._log_durations())
        durations /= durations.sum(axis=1, keepdims=True)
        states = np.empty(n_samples, dtype=int)
        state, t = rng.choice(self.n_states, p=self.startprob_), 0
        while t < n_samples:
            duration = 1 + rng.choice(self.max_duration_, p=durations[state])
            states[t : t + duration] = state
            t += duration
            row = self.transmat_[state]
            if row.sum() > 0:
                state = rng.choice(self.n_states, p=row / row.sum())
        X = np.empty((n_samples, self.means_.shape[1]))
        factors = np.linalg.cholesky(self.covariances_)
        noise = rng.standard_normal(X.shape)
        for i in range(self.n_states):
            rows = states == i
            X[rows] = self.means_[i] + noise[rows] @ factors[i].T
        return X, states

    @property
    def n_parameters_(self):
        """Free parameters, counted as hmmlearn does (every entry of A free).

        (N - 1) for pi, N (N - 2) for A (each row: N - 1 off-diagonal entries summing to
        1; N = 1 has none), N D means, N D (D + 1) / 2 covariances, 2 N durations (mean and
        spread). Zeros of A kept by a left-to-right initialisation are counted as free.
        """
        n, n_dims = self.n_states, self.n_dims_
        return int(
            (n - 1) + n * max(n - 2, 0) + n * n_dims + n * n_dims * (n_dims + 1) // 2 + 2 * n
        )

    def bic(self, X, lengths=None):
        """BIC = -2 log L + n_parameters_ log(n_samples); lower is better."""
        demos = self._sequences(X, lengths)
        n_samples = sum(len(demo) for demo in demos)
        return -2.0 * self.score(demos) + self.n_parameters_ * np.log(n_samples)

    def aic(self, X, lengths=None):
        """AIC = -2 log L + 2 n_parameters_; lower is better."""
        return -2.0 * self.score(self._sequences(X, lengths)) + 2.0 * self.n_parameters_

    def state_order(self, threshold=0.9):
        """The states in the order the model's timing alone visits them, or None.

        The order is fixed by the timing when pi puts at least ``threshold`` on one state,
        each state reached then moves on to one next state with probability at least
        ``threshold`` (or is never left: a zero row), and no state comes back before every
        state has been visited. Left-to-right models (init "time", "polyline") are such
        chains; k-means models often are not (several start states, branches, cycles).

        Returns
        -------
        list of int or None
        """
        self._check_fitted()
        state = int(np.argmax(self.startprob_))
        if self.startprob_[state] < threshold:
            return None
        order = [state]
        while len(order) < self.n_states:
            row = self.transmat_[state]
            if row.sum() == 0:
                break
            state = int(np.argmax(row))
            if row[state] < threshold * row.sum() or state in order:
                return None
            order.append(state)
        return order

    def check_weighting(self, weighting):
        """Warn (``UserWarning``) if a reproduction ``weighting`` is known to fail here.

        ``"temporal"`` weighs the states by the timing alone (eq. 12 without observations):
        when the timing does not fix the state sequence (:meth:`state_order` is None) it
        blends states from different parts of the task. Measured on LASA (N = 10, init
        "kmeans", GMR tracker): position RMSE 1.7-17.9 mm on such models against 1.1-5.9 mm
        with "forward" (docs/learning.md).
        """
        if weighting == "temporal" and self.state_order() is None:
            warnings.warn(
                "temporal weighting follows the HSMM's timing alone, and this model's timing "
                "does not fix its state sequence (several likely start states, branching or "
                "cyclic transitions; HSMM.state_order() is None): the reproduction can be "
                "wildly wrong. Use weighting='forward', or fit with init='time' or 'polyline'",
                stacklevel=2,
            )

    def _log_emission(self, demo_or_n_steps, observe):
        """(T, N) emission log-likelihoods, zeros when not observing."""
        if observe:
            demo = self._check_demo(demo_or_n_steps)
            return gaussian_log_pdf(demo, self.means_, self.covariances_)
        n_steps = demo_or_n_steps
        if isinstance(n_steps, np.ndarray):
            n_steps = len(self._check_demo(n_steps))
        if not isinstance(n_steps, (int, np.integer)) or n_steps < 1:
            raise ValueError(f"n_steps must be an integer >= 1, got {n_steps!r}")
        self._check_fitted()
        return np.zeros((int(n_steps), self.n_states))

    def log_forward_variable(self, demo_or_n_steps, *, observe=True):
        """log alpha_{i,t} of eq. 11: a segment of state i ends at step t.

        Parameters
        ----------
        demo_or_n_steps : array, shape (T, D), or int
            The observations, or (with ``observe=False``) the number of steps.
        observe : bool
            False drops the emission term (the timing alone).

        Returns
        -------
        array, shape (T, N)
        """
        log_emission = self._log_emission(demo_or_n_steps, observe)
        return _kernels.forward(log_emission, *self._log_parameters())[0]

    def forward_variable(self, demo_or_n_steps, *, observe=True):
        """State weights h_{i,t} = p(state i active at t | xi_0..t), normalised (eq. 12).

        The residual-duration form of the forward variable (eq. 11 summed over
        the remaining duration), which is what reproduction uses; see
        :mod:`hemg_drake.learning.reproduce` (a state the model never leaves
        holds once its segment ends).

        Parameters
        ----------
        demo_or_n_steps : array, shape (T, D), or int
        observe : bool

        Returns
        -------
        array, shape (T, N), rows summing to 1
        """
        log_emission = self._log_emission(demo_or_n_steps, observe)
        recursion = ResidualForward(self)
        predicted = recursion.initial()
        h = np.empty_like(log_emission)
        for t, log_b in enumerate(log_emission):
            h[t], predicted = recursion.step(predicted, log_b)
        return h

    # ------------------------------------------------------------ persistence
    def save(self, path):
        """Write the fitted model to ``path`` (NPZ with a format version), atomically."""
        self._check_fitted()
        save_fitted(path, self, FORMAT_VERSION, self.get_params())

    @classmethod
    def load(cls, path):
        """Read a model written by :meth:`save`.

        Raises ``FileNotFoundError`` for a missing file and ``ValueError``
        naming the file for a damaged one or another format version.
        """
        path = Path(path)
        arrays = load_npz(path, kind="HSMM model")
        version = arrays.get("format_version")
        if version is None:
            what = "a dataset (dataset.npz)" if "metadata" in arrays else "another kind of file"
            raise ValueError(
                f"{path}: not an HSMM model: it holds no format version, like {what}; fit "
                f"a model with hemg-drake learn"
            )
        if version.shape != () or int(version) != FORMAT_VERSION:
            raise ValueError(
                f"{path}: HSMM model format version {version}, this code reads "
                f"{FORMAT_VERSION} (fit the model again, e.g. hemg-drake learn)"
            )
        missing = [k for k in (*_FITTED, "settings", "max_duration_") if k not in arrays]
        if missing:
            raise ValueError(f"{path}: damaged HSMM model file, missing {missing}")
        try:
            model = cls(**json.loads(str(arrays["settings"])))
        except (TypeError, json.JSONDecodeError) as error:
            raise ValueError(f"{path}: damaged HSMM model settings ({error})") from None
        for name in _FITTED:
            setattr(model, name, arrays[name].astype(float))
        model.max_duration_ = int(arrays["max_duration_"])
        history = arrays.get("log_likelihood_history_", np.empty(0))  # optional: [] if absent
        model.log_likelihood_history_ = history.tolist()
        model.n_iter_ = len(model.log_likelihood_history_)
        model.converged_ = None
        model._check_loaded(path)
        return model

    def _check_loaded(self, path):
        n = self.n_states
        n_dims = self.means_.shape[1] if self.means_.ndim == 2 else -1
        shapes = {
            "startprob_": (n,), "transmat_": (n, n), "means_": (n, n_dims),
            "covariances_": (n, n_dims, n_dims), "duration_means_": (n,),
            "duration_stds_": (n,), "occupancy_": (n,), "data_range_": (2, n_dims),
        }  # fmt: skip
        for name, shape in shapes.items():
            value = getattr(self, name)
            if value.shape != shape:
                raise ValueError(
                    f"{path}: damaged HSMM model file, {name} has shape {value.shape}, "
                    f"expected {shape}"
                )
            if not np.all(np.isfinite(value)):
                raise ValueError(f"{path}: damaged HSMM model file, {name} holds NaN or inf")
        try:
            np.linalg.cholesky(self.covariances_)
        except np.linalg.LinAlgError:
            raise ValueError(
                f"{path}: damaged HSMM model file, covariances_ not positive definite"
            ) from None
        if np.any(self.data_range_[0] > self.data_range_[1]):
            raise ValueError(f"{path}: damaged HSMM model file, data_range_ minimum > maximum")
        if np.any(self.duration_stds_ <= 0) or self.max_duration_ < 1:
            raise ValueError(f"{path}: damaged HSMM model file, bad duration parameters")


def save_fitted(path, model, format_version, settings, **extra):
    """Write a fitted HSMM's arrays, d_max and history with a format version and the
    ``settings`` that rebuild it (JSON), plus ``extra`` arrays, atomically (NPZ)."""
    save_npz_atomic(
        path,
        format_version=np.array(format_version),
        settings=np.array(json.dumps(settings)),
        max_duration_=np.array(model.max_duration_),
        log_likelihood_history_=np.array(model.log_likelihood_history_, dtype=float),
        **extra,
        **{name: getattr(model, name) for name in _FITTED},
    )


_DEFAULTS = {
    name: parameter.default
    for name, parameter in inspect.signature(HSMM.__init__).parameters.items()
    if name in PARAMETERS
}


def segments(states):
    """The runs of a state sequence: arrays ``state``, ``start``, ``duration`` (steps).

    With no self-transitions in the model, each run of :meth:`HSMM.decode` is one segment.
    """
    states = np.asarray(states)
    if states.ndim != 1 or states.size == 0:
        raise ValueError(f"states must be a non-empty 1-D array, got shape {states.shape}")
    start = np.concatenate([[0], np.flatnonzero(np.diff(states)) + 1])
    duration = np.diff(np.concatenate([start, [len(states)]]))
    return states[start], start, duration


def select_n_states(X, candidates, *, lengths=None, criterion="bic", **parameters):
    """Fit an HSMM for each number of states and keep the one with the lowest BIC or AIC.

    Parameters
    ----------
    X : list of arrays (T_c, D), or array (n_samples, D)
    candidates : iterable of int
        Numbers of states to try.
    lengths : sequence of int, optional
        As for :meth:`HSMM.fit`.
    criterion : {"bic", "aic"}
    **parameters
        Other :class:`HSMM` parameters (the same for every candidate).

    Returns
    -------
    best : HSMM
        Fitted, the lowest criterion.
    scores : dict
        Criterion value per number of states.
    """
    if criterion not in ("bic", "aic"):
        raise ValueError(f"criterion must be 'bic' or 'aic', got {criterion!r}")
    candidates = list(candidates)
    if not candidates:
        raise ValueError("candidates is empty: give the numbers of states to try")
    demos = check_demos(split_sequences(X, lengths))
    scores, best = {}, None
    for n_states in candidates:
        model = HSMM(n_states, **parameters).fit(demos)
        scores[n_states] = float(getattr(model, criterion)(demos))
        if best is None or scores[n_states] < scores[best.n_states]:
            best = model
    return best, scores
