"""The number of HSMM states by an information criterion (BIC, AIC)."""

import numpy as np

from hemg_drake.learning.sequences import check_demos, fitted_sequences, split_sequences


class CriteriaMixin:
    """Free parameters, BIC and AIC of a fitted :class:`~hemg_drake.learning.hsmm.HSMM`
    (from its public API)."""

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
        demos = fitted_sequences(self, X, lengths)
        n_samples = sum(len(demo) for demo in demos)
        return -2.0 * self.score(demos) + self.n_parameters_ * np.log(n_samples)

    def aic(self, X, lengths=None):
        """AIC = -2 log L + 2 n_parameters_; lower is better."""
        return -2.0 * self.score(fitted_sequences(self, X, lengths)) + 2.0 * self.n_parameters_


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
    from hemg_drake.learning.hsmm import HSMM  # (hsmm imports this module)

    demos = check_demos(split_sequences(X, lengths))
    scores, best = {}, None
    for n_states in candidates:
        model = HSMM(n_states, **parameters).fit(demos)
        scores[n_states] = float(getattr(model, criterion)(demos))
        if best is None or scores[n_states] < scores[best.n_states]:
            best = model
    return best, scores
