"""Log-sum-exps over an explicit-duration HSMM's duration windows, compiled by numba.

What the time recursions of :mod:`hemg_drake.learning._kernels` sum at each (time, state):
a state's duration support, the emissions' running sums (a segment's log-likelihood is a
difference), and log sum exp over the finite entries of a transition row
(:func:`log_row`) or over a window of segment boundaries (:func:`window`). Of those terms
only a few are within NEGLIGIBLE nats of the largest (the segments' emission products fall by
hundreds of nats per step), so the window sums skip chunks of boundaries whose largest value
cannot reach the best term so far, looking at the window's two ends first. The kept terms'
exp() is :func:`exp_kept`. Indices: t time, i and j states, d duration in steps (1 ..
n_durations, at column d - 1).
"""

import numba
import numpy as np

_NEG_INF = -np.inf
# Terms more than this many nats below the largest are skipped in a log-sum-exp: together
# (at most n_durations of them) they change it by less than 1e-19 relative.
NEGLIGIBLE = 50.0

@numba.njit(cache=True)
def support(log_duration):
    """First and last duration index (0-based, inclusive) of each state with p_i(d) > 0."""
    n_states, n_durations = log_duration.shape
    first = np.zeros(n_states, dtype=np.int64)
    last = np.full(n_states, -1, dtype=np.int64)
    for i in range(n_states):
        for d in range(n_durations):
            if log_duration[i, d] > _NEG_INF:
                if last[i] < 0:
                    first[i] = d
                last[i] = d
    return first, last


@numba.njit(cache=True)
def cumulative(log_emission):
    """Per-state running sums, shape (N, T + 1): a segment's log-likelihood is a difference.

    State-major, like the other arrays the duration loops read, so that they read
    consecutive memory.
    """
    n_steps, n_states = log_emission.shape
    total = np.zeros((n_states, n_steps + 1))
    for i in range(n_states):
        for t in range(n_steps):
            total[i, t + 1] = total[i, t] + log_emission[t, i]
    return total


# exp() on (-NEGLIGIBLE, 0], where every kept term is: e^(-k/64) from a table times a
# degree-6 Taylor polynomial of the rest (|r| <= 1/128), within 2 ulp of np.exp (tested) at
# half its cost here, where it took 40 % of the duration sums' time.
_EXP_STEPS = 64
_EXP_TABLE = np.exp(-np.arange(int(NEGLIGIBLE) * _EXP_STEPS + 2) / _EXP_STEPS)


@numba.njit(cache=True, inline="always")
def exp_kept(x):
    """e^x for x in (-NEGLIGIBLE, 0] (exactly 1 at 0)."""
    k = int(-x * _EXP_STEPS + 0.5)
    r = x + k / _EXP_STEPS
    polynomial = 1.0 / 120.0 + r * (1.0 / 720.0)
    polynomial = 1.0 / 24.0 + r * polynomial
    polynomial = 1.0 / 6.0 + r * polynomial
    polynomial = 0.5 + r * polynomial
    polynomial = 1.0 + r * polynomial
    return _EXP_TABLE[k] * (1.0 + r * polynomial)


@numba.njit(cache=True)
def finite_entries(log_matrix):
    """(start, columns): row i of ``log_matrix`` (N, N) is finite at columns[start[i] :
    start[i + 1]] (increasing) only."""
    n_rows, n_columns = log_matrix.shape
    start = np.zeros(n_rows + 1, dtype=np.int64)
    columns = np.empty(n_rows * n_columns, dtype=np.int64)
    k = 0
    for i in range(n_rows):
        for j in range(n_columns):
            if log_matrix[i, j] > _NEG_INF:
                columns[k] = j
                k += 1
        start[i + 1] = k
    return start, columns[:k]


@numba.njit(cache=True, inline="always")
def log_row(log_row, log_values, columns, low, high, weights):
    """log sum_j exp(log_row[j] + log_values[j]) over j = columns[low:high] (the row's
    finite entries) as top and sum / e^top (0 if all -inf); terms over NEGLIGIBLE below the
    largest left out. weights[k - low] is left the k-th's exp(term - top) (0 if left out)."""
    top = _NEG_INF
    for k in range(low, high):
        j = columns[k]
        weights[k - low] = log_row[j] + log_values[j]
        if weights[k - low] > top:
            top = weights[k - low]
    total = 0.0
    for k in range(high - low):
        weights[k] = exp_kept(weights[k] - top) if weights[k] > top - NEGLIGIBLE else 0.0
        total += weights[k]
    return top, total


# Positions per chunk: the duration loops skip a whole chunk of segment boundaries whose
# largest log value is too low to matter, instead of looking at each.
CHUNK = 8


@numba.njit(cache=True, inline="always")
def push(chunk_top, row, position, value):
    """Keep chunk_top[row, c] the largest value pushed at a position of chunk c."""
    c = position // CHUNK
    if value > chunk_top[row, c]:
        chunk_top[row, c] = value


@numba.njit(cache=True, inline="always")
def window(values, chunk_top, weights, offset, low, high, bound, descending, kept, where):
    """sum_{p = low .. high} exp(values[p] + weights[offset + p]) as top and sum / e^top.

    Terms more than NEGLIGIBLE below the largest are left out; a chunk whose
    ``chunk_top`` plus ``bound`` (the largest weight) is that far below the best term so far
    is not looked at. The window's end chunks go first (on steep stretches the largest term
    is at one of them), then the others from the newest (``descending``: the highest
    position). Returns top (-inf if no term), the sum of exp(term - top) and n: the kept
    terms' exp(term - top) are left in ``kept[:n]``, their positions in ``where[:n]``.
    """
    n = 0
    top = _NEG_INF
    newest, oldest = low // CHUNK, high // CHUNK
    step = 1
    if descending:
        newest, oldest, step = oldest, newest, -1
    for k in range(abs(oldest - newest) + 1):
        c = newest if k == 0 else (oldest if k == 1 else newest + (k - 1) * step)
        if chunk_top[c] == _NEG_INF or chunk_top[c] + bound < top - NEGLIGIBLE:
            continue
        for p in range(max(low, c * CHUNK), min(high, c * CHUNK + CHUNK - 1) + 1):
            # Without branches (whether a term is kept is unpredictable): always written,
            # kept by counting it.
            value = values[p] + weights[offset + p]
            kept[n] = value
            where[n] = p
            n += value > top - NEGLIGIBLE
            top = max(top, value)
    total = 0.0
    for k in range(n):
        kept[k] = exp_kept(kept[k] - top) if kept[k] > top - NEGLIGIBLE else 0.0
        total += kept[k]
    return top, total, n


@numba.njit(cache=True)
def workspace(log_emission, log_duration):
    """What both passes need: each state's support and largest log p_i(d), the running
    sums of the emissions (:func:`cumulative`), empty chunk maxima (:func:`push`) with
    the state-major array of the duration sums' values they bound, and scratch for
    :func:`log_row` and :func:`window`."""
    n_steps, n_states = log_emission.shape
    n_durations = log_duration.shape[1]
    first, last = support(log_duration)
    bound = np.full(n_states, _NEG_INF)
    for i in range(n_states):
        if last[i] >= first[i]:
            bound[i] = log_duration[i, first[i] : last[i] + 1].max()
    chunk_top = np.full((n_states, n_steps // CHUNK + 1), _NEG_INF)
    values = np.empty((n_states, n_steps))
    weights = np.empty(n_states)
    kept = np.empty(n_durations)
    where = np.empty(n_durations, dtype=np.int64)
    return (first, last, bound, cumulative(log_emission), chunk_top, values, weights, kept,
            where)  # fmt: skip


