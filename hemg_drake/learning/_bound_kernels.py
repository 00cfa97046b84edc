"""Upper bounds on the rest of a sequence's log-likelihood, compiled by numba.

With them the E-step (:func:`hemg_drake.learning._kernels.expectation`) leaves out the
segment starts and ends whose paths cannot carry a posterior above double precision's
underflow. Apart from :mod:`hemg_drake.learning._kernels`: numba's on-disk cache
(``cache=True``) notices changes to a kernel's own file only, so neither calls the other's
compiled functions.
"""

import numba
import numpy as np

_NEG_INF = -np.inf


@numba.njit(cache=True)
def suffix_bound(log_emission, bounds, log_transmat, log_duration):
    """:func:`_one` of each sequence c (rows bounds[c] : bounds[c + 1]), concatenated."""
    starts = np.empty(log_emission.shape)
    ends = np.empty(log_emission.shape)
    for c in range(len(bounds) - 1):
        rows = slice(bounds[c], bounds[c + 1])
        starts[rows], ends[rows] = _one(log_emission[rows], log_transmat, log_duration)
    return starts, ends


@numba.njit(cache=True)
def _one(log_emission, log_transmat, log_duration):
    """Upper bounds on what the rest of a sequence can add: ``starts[t, i]`` on
    log p(xi_t..T-1 | a segment of i starts at t), ``ends[t, i]`` on
    log p(xi_t+1..T-1 | one ends at t).

    The best state sequence allowed by A's zeros, at any durations: a segment's
    duration weights add up to at most S = max_i sum_d p_i(d) (about 1; counted once per
    step if above 1) and a row of A to at most 1, so the sum over paths is at most the best
    path's emissions times that. O(T (N + nonzeros of A)), no exp.
    """
    n_steps, n_states = log_emission.shape
    per_step = 0.0
    for i in range(n_states):
        mass = 0.0
        for d in range(log_duration.shape[1]):
            if log_duration[i, d] > _NEG_INF:
                mass += np.exp(log_duration[i, d])
        per_step = max(per_step, np.log(mass) if mass > 0.0 else 0.0)
    starts = np.empty((n_steps, n_states))
    ends = np.empty((n_steps, n_states))
    ends[n_steps - 1] = 0.0  # the last segment ends with the sequence
    for t in range(n_steps - 1, -1, -1):
        for i in range(n_states):
            if t < n_steps - 1:
                best = _NEG_INF  # leave i after t
                for j in range(n_states):
                    if log_transmat[i, j] > _NEG_INF:
                        best = max(best, starts[t + 1, j])
                ends[t, i] = best
            stay = starts[t + 1, i] if t < n_steps - 1 else _NEG_INF
            starts[t, i] = log_emission[t, i] + per_step + max(stay, ends[t, i])
    return starts, ends
