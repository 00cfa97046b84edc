"""Decoding kernels of the explicit-duration HSMM, compiled by numba: segmental Viterbi and
the state posteriors from the segment posteriors of :func:`._kernels.expectation`.

They take what they need of :mod:`hemg_drake.learning._sum_kernels` (a state's duration
support, the emissions' running sums) as arguments, from Python: numba's on-disk cache
(``cache=True``) notices changes to a kernel's own file only, so no compiled function here
calls one there.
"""

import numba
import numpy as np

from hemg_drake.learning import _sum_kernels

_NEG_INF = -np.inf


def viterbi(log_emission, log_startprob, log_transmat, log_duration):
    """Segmental Viterbi: the most likely segmentation of one sequence.

    The max-product version of :func:`hemg_drake.learning._kernels.forward` (a complete
    segment ends the sequence).

    Parameters
    ----------
    log_emission, log_startprob, log_transmat, log_duration : arrays
        As for :func:`hemg_drake.learning._kernels.forward`.

    Returns
    -------
    log_probability : float
        log p(xi, best segmentation); -inf if no segmentation is possible.
    states : array of int, shape (T,)
        The state active at each step (all -1 if impossible).
    """
    first, last = _sum_kernels.support(log_duration)
    return _viterbi(log_emission, log_startprob, log_transmat, log_duration, first, last,
                    _sum_kernels.cumulative(log_emission))  # fmt: skip


@numba.njit(cache=True)
def _viterbi(log_emission, log_startprob, log_transmat, log_duration, first, last, total):
    """:func:`viterbi` given each state's duration support and the emissions' running sums."""
    n_steps, n_states = log_emission.shape
    best = np.empty((n_steps, n_states))  # a segment of i ends at t
    best_in = np.empty((n_states, n_steps))  # a segment of i starts at t, state-major
    previous = np.full((n_steps, n_states), -1, dtype=np.int64)  # state before that segment
    length = np.zeros((n_steps, n_states), dtype=np.int64)  # its duration
    for t in range(n_steps):
        for i in range(n_states):
            if t == 0:
                best_in[i, t] = log_startprob[i]
                continue
            top = _NEG_INF
            for j in range(n_states):
                value = best[t - 1, j] + log_transmat[j, i]
                if value > top:
                    top = value
                    previous[t, i] = j
            best_in[i, t] = top
        for i in range(n_states):
            top = _NEG_INF
            end = total[i, t + 1]
            for d in range(first[i] + 1, min(last[i] + 1, t + 1) + 1):
                begin = t - d + 1
                value = best_in[i, begin] + log_duration[i, d - 1] + end - total[i, begin]
                if value > top:
                    top = value
                    length[t, i] = d
            best[t, i] = top
    states = np.full(n_steps, -1, dtype=np.int64)
    state = np.argmax(best[n_steps - 1])
    log_probability = best[n_steps - 1, state]
    if log_probability == _NEG_INF:
        return log_probability, states
    t = n_steps - 1
    while t >= 0:
        begin = t - length[t, state] + 1
        states[begin : t + 1] = state
        state_before = previous[begin, state]
        t = begin - 1
        state = state_before
    return log_probability, states


@numba.njit(cache=True)
def occupancy(starts, ends, bounds):
    """p(state i active at t | its sequence), shape (T, N), from the segment posteriors.

    Segments of i started at or before t minus those ended before t, within each sequence
    c (rows bounds[c] : bounds[c + 1]), clipped to [0, 1] against round-off.
    """
    n_states = starts.shape[1]
    gamma = np.empty(starts.shape)
    for c in range(len(bounds) - 1):
        for i in range(n_states):
            active = 0.0
            for t in range(bounds[c], bounds[c + 1]):
                active += starts[t, i]
                if t > bounds[c]:
                    active -= ends[t - 1, i]
                gamma[t, i] = min(max(active, 0.0), 1.0)
    return gamma
