"""Hidden semi-Markov model with explicit Gaussian durations, trained by EM (eqs. 4-11).

:class:`HSMM` is the estimator: its parameters, :meth:`HSMM.fit` and the likelihoods. Its
other methods come from one module per job: the initialisations (:mod:`.hsmm_init`), the
EM steps (:mod:`.hsmm_em`), decoding, sampling and forward variables
(:mod:`.hsmm_inference`), BIC/AIC (:mod:`.model_selection`) and the model file
(:mod:`.hsmm_io`). Every public name of those modules is importable from here.
"""

import numpy as np
from sklearn.base import BaseEstimator

from hemg_drake.learning import hsmm_em
from hemg_drake.learning.gmr import gaussian_log_pdf
from hemg_drake.learning.hsmm_inference import InferenceMixin, segments  # noqa: F401
from hemg_drake.learning.hsmm_init import (  # noqa: F401
    DURATION_STD_FLOOR,
    initialise,
    polyline_segments,
)
from hemg_drake.learning.hsmm_io import (  # noqa: F401
    FITTED,
    FORMAT_VERSION,
    PersistenceMixin,
    save_fitted,
)
from hemg_drake.learning.hsmm_params import INITS, check_parameters  # noqa: F401
from hemg_drake.learning.model_selection import CriteriaMixin, select_n_states  # noqa: F401
from hemg_drake.learning.sequences import (
    check_demos,
    check_fitted,
    fitted_sequences,
    position_count,
    split_sequences,
)


class HSMM(InferenceMixin, CriteriaMixin, PersistenceMixin, BaseEstimator):
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

    The estimator API follows hmmlearn and scikit-learn: a
    :class:`sklearn.base.BaseEstimator` (``get_params`` / ``set_params``, ``clone``, its
    repr), whose constructor only stores the parameters and whose :meth:`fit` checks them;
    ``fit(X, lengths)``, ``score``, ``decode`` (segmental Viterbi), ``sample``, ``bic`` /
    ``aic``. The scikit-learn estimator checks it passes, and those that do not apply to
    a sequence model, are listed in docs/learning.md.

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
    random_state : int
        Seed of every random draw (k-means++, empty states); an integer >= 0, never None,
        so that the same data give the same model. (Model files written with the former
        name ``seed`` still load.)

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
    n_features_in_ : int
        D (scikit-learn's name; set by fit, not saved: ``n_dims_`` is always there).
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
        random_state=0,
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
        self.random_state = random_state

    def __sklearn_is_fitted__(self):
        return all(hasattr(self, name) for name in FITTED)

    # ------------------------------------------------------------------ layout
    @property
    def n_dims_(self):
        """D of the fitted model."""
        check_fitted(self)
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

    def _n_position(self):
        return position_count(self.n_dims_, self.n_position)

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
        check_parameters(self)
        demos = check_demos(split_sequences(X, lengths))
        for c, demo in enumerate(demos):
            if len(demo) < self.n_states:
                raise ValueError(
                    f"demonstration {c + 1} has {len(demo)} samples (steps), fewer than the "
                    f"N = {self.n_states} states"
                )
        samples = np.concatenate(demos)
        self.n_features_in_ = samples.shape[1]
        self.data_range_ = np.stack([samples.min(axis=0), samples.max(axis=0)])
        scale = samples.std(axis=0)
        # A constant dimension's std is 0 or rounding noise (a held coordinate, the gradient
        # of one): a floor relative to that is no floor, so a dimension whose spread is
        # below 1e-12 of the data's largest magnitude is floored in its own units.
        scale[scale <= 1e-12 * np.abs(samples).max()] = 1.0
        initialise(self, demos, samples, scale)
        self.log_likelihood_history_ = []
        self.converged_ = False
        n_samples = len(samples)
        outer = (samples[:, :, None] * samples[:, None, :]).reshape(n_samples, -1)
        guesses = None  # each demonstration's log-likelihood at the previous iteration
        for self.n_iter_ in range(1, self.n_iter + 1):
            stats = hsmm_em.expectation(self, demos, outer, guesses)
            guesses = stats["sequences"]
            if not np.isfinite(stats["log_likelihood"]):
                raise ValueError(
                    "the demos cannot be segmented into at most "
                    f"max_duration = {self.max_duration_} steps per state visit; "
                    "raise max_duration or n_states"
                )
            history = self.log_likelihood_history_
            history.append(stats["log_likelihood"])
            hsmm_em.maximisation(self, stats, scale)
            if len(history) > 1 and history[-1] - history[-2] < self.tol * n_samples:
                self.converged_ = True
                break
        return self

    def floor_covariances(self, covariances, scale):
        """The constrained covariance M-step: eigenvalues of ``covariances`` (N, D, D)
        floored at ``reg_covar`` in units of ``scale`` (D,), the per-dimension spread of the
        training data. A subclass that constrains the covariances further overrides it."""
        return hsmm_em.floor_covariances(covariances, scale, self.reg_covar)

    def log_durations(self):
        """log p_i(d) for d = 1 .. max_duration_, shape (N, d_max); -inf beyond the
        support |d - mu_i^D| <= 10 sigma_i^D (below e^-50 of the peak)."""
        check_fitted(self)
        return hsmm_em.log_durations(self.duration_means_, self.duration_stds_, self.max_duration_)

    # -------------------------------------------------------------- likelihood
    def _demo_posteriors(self, demo):
        """:func:`hsmm_em.posteriors` of one demonstration (checked)."""
        demo = check_demos([demo], n_dims=self.n_dims_)[0]
        log_emission = gaussian_log_pdf(demo, self.means_, self.covariances_)
        return hsmm_em.posteriors(log_emission, hsmm_em.log_parameters(self))

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
        return float(sum(self.log_likelihood(demo) for demo in fitted_sequences(self, X, lengths)))
