"""What a fitted HSMM says about sequences beyond their likelihood.

Segmental Viterbi decoding and its segments, sampling, the forward variable (eqs. 11-12)
and the order in which the timing visits the states. :class:`InferenceMixin` holds these
methods of :class:`~hemg_drake.learning.hsmm.HSMM`; they use its public API only.
"""

import warnings

import numpy as np

from hemg_drake.learning import _kernels, _segment_kernels
from hemg_drake.learning.forward import ResidualForward
from hemg_drake.learning.gmr import gaussian_log_pdf
from hemg_drake.learning.hsmm_em import log_parameters
from hemg_drake.learning.sequences import check_demos, check_fitted, fitted_sequences


class InferenceMixin:
    """Decoding, sampling and forward variables of a fitted
    :class:`~hemg_drake.learning.hsmm.HSMM`."""

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
        log_parameters_ = log_parameters(self)
        total, states = 0.0, []
        for c, demo in enumerate(fitted_sequences(self, X, lengths)):
            log_emission = gaussian_log_pdf(demo, self.means_, self.covariances_)
            log_probability, path = _segment_kernels.viterbi(log_emission, *log_parameters_)
            if not np.isfinite(log_probability):
                raise ValueError(f"the model cannot produce sequence {c} (probability 0)")
            total += log_probability
            states.append(path)
        return float(total), np.concatenate(states)

    def sample(self, n_samples, random_state=0):
        """Draw one sequence from the model (hmmlearn's ``sample``).

        The first state from pi, each duration from p_i(d) normalised over its support,
        observations from N(mu_i, Sigma_i), the next state from row i of A (a state whose
        row is zero, never left in training, continues). The last segment is cut at
        ``n_samples``.

        Parameters
        ----------
        n_samples : int >= 1
        random_state : int or numpy.random.Generator
            Seed of the draws.

        Returns
        -------
        X : array, shape (n_samples, D)
        states : array of int, shape (n_samples,)
        """
        check_fitted(self)
        if not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
            raise ValueError(f"n_samples must be an integer >= 1, got {n_samples!r}")
        rng = np.random.default_rng(random_state)
        durations = np.exp(self.log_durations())
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
        check_fitted(self)
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
            demo = check_demos([demo_or_n_steps], n_dims=self.n_dims_)[0]
            return gaussian_log_pdf(demo, self.means_, self.covariances_)
        n_steps = demo_or_n_steps
        if isinstance(n_steps, np.ndarray):
            n_steps = len(check_demos([n_steps], n_dims=self.n_dims_)[0])
        if not isinstance(n_steps, (int, np.integer)) or n_steps < 1:
            raise ValueError(f"n_steps must be an integer >= 1, got {n_steps!r}")
        check_fitted(self)
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
        return _kernels.forward(log_emission, *log_parameters(self))[0]

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
