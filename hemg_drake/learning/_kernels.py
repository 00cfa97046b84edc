"""Time recursions of the explicit-duration HSMM in log space, compiled by numba.

Step t needs step t - 1, so the loops are JIT-compiled. Indices: t time, i and j states, d
duration in steps (1 .. n_durations, at column d - 1). The cost is the duration sums, which
:mod:`._sum_kernels` computes (skipping the negligible terms); everything stays in log space.
Viterbi and the state posteriors are in :mod:`._segment_kernels`, the E-step's bounds in
:mod:`._bound_kernels`, the emissions' distances and the reproduction's step in
:mod:`._step_kernels`.
"""

import hashlib
from pathlib import Path

import numba
import numpy as np

from hemg_drake.learning import _sum_kernels
from hemg_drake.learning._sum_kernels import finite_entries, log_row, push, window, workspace

_NEG_INF = -np.inf
# A posterior below e^-745 is 0 in double precision (the smallest subnormal is 4.9e-324):
# the E-step leaves out segments whose paths carry less than e^-UNDERFLOW of the likelihood.
UNDERFLOW = 750.0
# numba's on-disk cache notices changes to a kernel's own file only, and the kernels here
# compile _sum_kernels' functions into theirs: they are cached only while _sum_kernels.py is
# the file they were written against (its SHA-256 here). Otherwise they compile afresh at each
# import, and tests/learning/test_hsmm_kernels.py fails until this digest is updated (which
# changes this file, so that its cache is renewed). Line ends are read as "\n" (a checkout
# with CRLF keeps its cache).
SUM_KERNELS_SHA256 = "6b84a4418e16ea855f72238c67f6c6d76cf6feaaa1d51c162aeccd32c80052ed"
_SUM_KERNELS_SOURCE = Path(_sum_kernels.__file__).read_bytes().replace(b"\r\n", b"\n")
_CACHED = hashlib.sha256(_SUM_KERNELS_SOURCE).hexdigest() == SUM_KERNELS_SHA256


@numba.njit(cache=_CACHED)
def forward(log_emission, log_startprob, log_transmat, log_duration):
    """Segment forward variables (eq. 11) of one sequence, every path kept.

    Parameters
    ----------
    log_emission : array, shape (T, N)
        log N(xi_t | mu_i, Sigma_i) (all zeros for "no observation").
    log_startprob, log_transmat : arrays, shape (N,), (N, N)
        log pi_i; log a_ji at [j, i] (-inf entries are skipped).
    log_duration : array, shape (N, n_durations)
        log p_i(d) at [i, d - 1]; -inf outside a state's support, which the loops skip
        (so the cost is O(T N w) for supports of w durations, not O(T N n_durations)).

    Returns
    -------
    log_alpha, log_alpha_in : arrays, shape (T, N)
        log p(xi_0..t, a segment of i ends at t), log p(xi_0..t-1, one starts at t).
    """
    none = np.zeros((0, 0))
    return forward_pruned(log_emission, log_startprob, log_transmat, log_duration, _NEG_INF,
                    (none, none))  # fmt: skip


@numba.njit(cache=_CACHED)
def forward_pruned(log_emission, log_startprob, log_transmat, log_duration, floor, suffix):
    """:func:`forward` with the segment starts and ends that cannot matter left out.

    A segment start (end) of i at t whose forward value plus ``suffix[0][t, i]``
    (``suffix[1][t, i]``), bounds on the rest's log-likelihood
    (:func:`._bound_kernels.suffix_bound`), is below ``floor`` is set to -inf: the paths
    through it carry at most e^floor. ``floor`` -inf keeps all (``suffix`` not read).
    """
    suffix_starts, suffix_ends = suffix
    n_steps, n_states = log_emission.shape
    n_durations = log_duration.shape[1]
    # boundary[i, b] = log alpha_in - the emissions before b: a segment's term is
    # boundary[i, b] + log p_i(d) + total[i, t + 1].
    first, last, bound, total, chunk_top, boundary, weights, kept, where = workspace(
        log_emission, log_duration
    )
    reversed_duration = np.ascontiguousarray(log_duration[:, ::-1])  # [i, n_durations - d]
    log_transmat_T = np.ascontiguousarray(log_transmat.T)
    # The transitions into each state that can happen (a left-to-right model has one).
    start, predecessors = finite_entries(log_transmat_T)
    log_alpha = np.empty((n_steps, n_states))
    log_alpha_in = np.empty((n_steps, n_states))
    newest = np.full(n_states, -1)  # the last step at which a segment of i can start
    for t in range(n_steps):
        for i in range(n_states):
            if t == 0:
                log_alpha_in[0, i] = log_startprob[i]
            else:
                top, weight = log_row(log_transmat_T[i], log_alpha[t - 1], predecessors,
                                       start[i], start[i + 1], weights)  # fmt: skip
                log_alpha_in[t, i] = top + np.log(weight) if weight > 0.0 else _NEG_INF
            if floor > _NEG_INF and log_alpha_in[t, i] + suffix_starts[t, i] < floor:
                log_alpha_in[t, i] = _NEG_INF
            boundary[i, t] = log_alpha_in[t, i] - total[i, t]
            push(chunk_top, i, t, boundary[i, t])
            if log_alpha_in[t, i] > _NEG_INF:
                newest[i] = t
        for i in range(n_states):
            # Durations d = first + 1 .. min(last + 1, t + 1): segment xi_{b..t}, b = t - d + 1.
            low, high = max(0, t - last[i]), t - first[i]
            log_alpha[t, i] = _NEG_INF
            if high >= low and newest[i] >= low:  # (else no segment of i can end at t)
                top, weight, _ = window(boundary[i], chunk_top[i], reversed_duration[i],
                                         n_durations - 1 - t, low, high, bound[i], True, kept,
                                         where)  # fmt: skip
                if weight > 0.0:
                    log_alpha[t, i] = total[i, t + 1] + top + np.log(weight)
                    if floor > _NEG_INF and log_alpha[t, i] + suffix_ends[t, i] < floor:
                        log_alpha[t, i] = _NEG_INF
    return log_alpha, log_alpha_in


@numba.njit(cache=_CACHED)
def backward(log_emission, log_transmat, log_duration, log_alpha, log_alpha_in, log_likelihood):
    """Backward variables and the expected counts of one sequence.

    Parameters
    ----------
    log_emission, log_transmat, log_duration : arrays
        As for :func:`forward`.
    log_alpha, log_alpha_in : arrays, shape (T, N)
        From :func:`forward`.
    log_likelihood : float
        log p(xi_0..T-1), a segment ending at T - 1.

    Returns
    -------
    log_beta, log_beta_in : arrays, shape (T, N)
        log p(xi_t+1..T-1 | a segment of i ends at t), log p(xi_t..T-1 | one starts at t),
        where log_alpha (log_alpha_in) is finite; -inf elsewhere: no path gets there, and
        leaving it out is exact for the others (a segment's paths reach both its ends).
    transition_counts, duration_counts : arrays, shape (N, N), (N, n_durations)
        Expected numbers of transitions i -> j at [i, j], of segments of i lasting d.
    starts, ends : arrays, shape (T, N)
        p(a segment of state i starts at t | all), p(one ends at t | all).
    """
    n_steps, n_states = log_emission.shape
    n_durations = log_duration.shape[1]
    # end[i, e] = the emissions up to e + log beta_e: a segment's term is
    # end[i, e] + log p_i(d) - total[i, s].
    first, last, bound, total, chunk_top, end, weights, kept, where = workspace(
        log_emission, log_duration
    )
    start, successors = finite_entries(log_transmat)  # the transitions out of each state
    log_beta = np.empty((n_steps, n_states))
    log_beta_in = np.empty((n_steps, n_states))
    starts = np.zeros((n_steps, n_states))
    ends = np.zeros((n_steps, n_states))
    transition_counts = np.zeros((n_states, n_states))
    duration_counts = np.zeros((n_states, n_durations))
    for s in range(n_steps - 1, -1, -1):
        for i in range(n_states):
            if s == n_steps - 1:
                log_beta[s, i] = 0.0
                if log_alpha[s, i] > _NEG_INF:
                    ends[s, i] = np.exp(log_alpha[s, i] - log_likelihood)
            elif log_alpha[s, i] == _NEG_INF:
                log_beta[s, i] = _NEG_INF  # not reached: left out (see Returns)
            else:
                top, weight = log_row(log_transmat[i], log_beta_in[s + 1], successors,
                                       start[i], start[i + 1], weights)  # fmt: skip
                log_beta[s, i] = top + np.log(weight) if weight > 0.0 else _NEG_INF
                if weight > 0.0:
                    # p(segment of i ends at s | all), and the transitions i -> j it makes.
                    scale = np.exp(top + log_alpha[s, i] - log_likelihood)
                    ends[s, i] = weight * scale
                    if scale > 0.0:  # (most states' posterior underflows: adding 0 is a no-op)
                        for k in range(start[i], start[i + 1]):
                            transition_counts[i, successors[k]] += weights[k - start[i]] * scale
            end[i, s] = total[i, s + 1] + log_beta[s, i]
            push(chunk_top, i, s, end[i, s])
        for i in range(n_states):
            # Durations d = first + 1 .. min(last + 1, T - s): segment xi_{s..e}, e = s + d - 1.
            low, high = s + first[i], min(s + last[i], n_steps - 1)
            log_beta_in[s, i] = _NEG_INF
            if high < low or log_alpha_in[s, i] == _NEG_INF:  # (not reached: left out)
                continue
            top, weight, n_kept = window(end[i], chunk_top[i], log_duration[i], -s, low, high,
                                          bound[i], False, kept, where)  # fmt: skip
            if weight == 0.0:
                continue
            log_beta_in[s, i] = top + np.log(weight) - total[i, s]
            # p(segment of i from s to e | all), added up by duration, and its start.
            scale = np.exp(top - total[i, s] + log_alpha_in[s, i] - log_likelihood)
            if scale > 0.0:
                for k in range(n_kept):
                    duration_counts[i, where[k] - s] += kept[k] * scale
            starts[s, i] = weight * scale
    return log_beta, log_beta_in, transition_counts, duration_counts, starts, ends


_LOG_2 = np.log(2.0)


@numba.njit(cache=_CACHED, inline="always")
def _logaddexp(x, y):
    """log(e^x + e^y), the way numpy's logaddexp computes it (so the same to the bit)."""
    if x == y:
        return x + _LOG_2
    difference = x - y
    if difference > 0:
        return x + np.log1p(np.exp(-difference))
    if difference <= 0:
        return y + np.log1p(np.exp(difference))
    return difference  # NaN


@numba.njit(cache=_CACHED)
def expectation(log_emission, bounds, log_startprob, log_transmat, log_duration, guesses,
                suffix_starts, suffix_ends):
    """The E-step over all sequences in one call: :func:`forward` and :func:`backward` of
    each, their counts added up in the sequences' order.

    Segment starts and ends whose paths carry under e^-UNDERFLOW of a sequence's likelihood
    (bounded by ``suffix_*``) are left out, with the results of every path: their posteriors
    underflow to 0 when kept, and together (at most 2 T N) they move the others by under
    e^-700 relative. The forward pass drops those below ``guesses[c] - UNDERFLOW -
    log(2 T N)``, ``guesses[c]`` a guess of sequence c's log-likelihood (the previous EM
    iteration's; -inf keeps all); if it then finds less than the guess minus 1 nat, it runs
    again with the floor from what it found (dropping less finds at least as much). The
    backward pass skips what the forward left out.

    Parameters
    ----------
    log_emission : array, shape (T, N)
        All sequences' emissions, concatenated.
    bounds : array of int, shape (C + 1,)
        Sequence c is rows bounds[c] : bounds[c + 1].
    log_startprob, log_transmat, log_duration : arrays
        As for :func:`forward`.
    guesses : array, shape (C,)
    suffix_starts, suffix_ends : arrays, shape (T, N)
        :func:`._bound_kernels.suffix_bound` of the sequences (not read if no guess).

    Returns
    -------
    log_likelihood : float
        sum_c log p(sequence c); not finite as soon as one sequence cannot be produced
        (the later ones are then not computed, and the other outputs are incomplete).
    sequences : array, shape (C,)
        log p(sequence c).
    starts, ends, transitions, durations : arrays
        :func:`backward`'s, the first two of each sequence in its rows, the others summed.
    """
    n_states = log_emission.shape[1]
    log_likelihood = 0.0
    sequences = np.full(len(bounds) - 1, _NEG_INF)
    starts = np.zeros(log_emission.shape)
    ends = np.zeros(log_emission.shape)
    transitions = np.zeros((n_states, n_states))
    durations = np.zeros(log_duration.shape)
    for c in range(len(bounds) - 1):
        emission = log_emission[bounds[c] : bounds[c + 1]]
        suffix = (suffix_starts[bounds[c] : bounds[c + 1]], suffix_ends[bounds[c] : bounds[c + 1]])
        margin = UNDERFLOW + np.log(2.0 * emission.size)
        floor = guesses[c] - margin if guesses[c] > _NEG_INF else _NEG_INF
        for _ in range(2):
            log_alpha, log_alpha_in = forward_pruned(
                emission, log_startprob, log_transmat, log_duration, floor, suffix
            )
            sequence = _NEG_INF  # logaddexp.reduce(log_alpha[-1])
            for i in range(n_states):
                sequence = _logaddexp(sequence, log_alpha[-1, i])
            if floor == _NEG_INF or sequence >= guesses[c] - 1.0:
                break
            floor = sequence - margin if sequence > _NEG_INF else _NEG_INF
        sequences[c] = sequence
        log_likelihood += sequence
        if not np.isfinite(sequence):
            break
        _, _, counts, duration_counts, segment_starts, segment_ends = backward(
            emission, log_transmat, log_duration, log_alpha, log_alpha_in, sequence
        )
        starts[bounds[c] : bounds[c + 1]] = segment_starts
        ends[bounds[c] : bounds[c + 1]] = segment_ends
        transitions += counts
        durations += duration_counts
    return log_likelihood, sequences, starts, ends, transitions, durations
