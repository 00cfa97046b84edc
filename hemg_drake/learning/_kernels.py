"""Time recursions of the explicit-duration HSMM in log space, compiled by numba.

The recursions over time cannot be vectorised (step t needs step t - 1), and a
numpy expression per time step costs more in call overhead than the work
itself, so these loops are JIT-compiled (``cache=True``: compiled once per
machine). Indices: t time, i and j states, d duration in steps (1 ..
n_durations, stored at column d - 1).
"""

import numba
import numpy as np

_NEG_INF = -np.inf
# Terms more than this many nats below the largest are skipped in a log-sum-exp:
# together (at most n_durations of them) they change it by less than 1e-19
# relative, below double precision, and skipping their exp() saves most of
# the time, since durations far from a state's mean are that unlikely.
_NEGLIGIBLE = 50.0


@numba.njit(cache=True)
def _logsumexp(values, n):
    """log(sum(exp(values[:n]))), -inf if every value is -inf."""
    top = _NEG_INF
    for k in range(n):
        if values[k] > top:
            top = values[k]
    if top == _NEG_INF:
        return _NEG_INF
    total = 0.0
    for k in range(n):
        if values[k] > top - _NEGLIGIBLE:
            total += np.exp(values[k] - top)
    return top + np.log(total)


@numba.njit(cache=True)
def _support(log_duration):
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
def _cumulative(log_emission):
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


@numba.njit(cache=True)
def _logsumexp_top(values, n, top):
    """log(sum(exp(values[:n]))) given their maximum ``top``."""
    if top == _NEG_INF:
        return _NEG_INF
    total = 0.0
    for k in range(n):
        if values[k] > top - _NEGLIGIBLE:
            total += np.exp(values[k] - top)
    return top + np.log(total)


@numba.njit(cache=True)
def forward(log_emission, log_startprob, log_transmat, log_duration):
    """Segment forward variables (eq. 11) of one sequence.

    Parameters
    ----------
    log_emission : array, shape (T, N)
        log N(xi_t | mu_i, Sigma_i) (all zeros for "no observation").
    log_startprob : array, shape (N,)
    log_transmat : array, shape (N, N)
        log a_ji at [j, i].
    log_duration : array, shape (N, n_durations)
        log p_i(d) at [i, d - 1]; -inf outside a state's support, which the loops skip
        (so the cost is O(T N w) for supports of w durations, not O(T N n_durations)).

    Returns
    -------
    log_alpha : array, shape (T, N)
        log p(xi_0..t, a segment of state i ends at t).
    log_alpha_in : array, shape (T, N)
        log p(xi_0..t-1, a segment of state i starts at t).
    """
    n_steps, n_states = log_emission.shape
    n_durations = log_duration.shape[1]
    first, last = _support(log_duration)
    total = _cumulative(log_emission)
    log_alpha = np.empty((n_steps, n_states))
    alpha_in = np.empty((n_states, n_steps))  # log_alpha_in, state-major (see _cumulative)
    terms = np.empty(max(n_durations, n_states))
    for t in range(n_steps):
        for i in range(n_states):
            if t == 0:
                alpha_in[i, t] = log_startprob[i]
            else:
                for j in range(n_states):
                    terms[j] = log_alpha[t - 1, j] + log_transmat[j, i]
                alpha_in[i, t] = _logsumexp(terms, n_states)
        for i in range(n_states):
            # Durations d = first + 1 .. min(last + 1, t + 1); segment xi_{t-d+1..t}.
            n_terms = 0
            top = _NEG_INF
            end = total[i, t + 1]
            for d in range(first[i] + 1, min(last[i] + 1, t + 1) + 1):
                begin = t - d + 1
                value = alpha_in[i, begin] + log_duration[i, d - 1] + end - total[i, begin]
                terms[n_terms] = value
                top = max(top, value)
                n_terms += 1
            log_alpha[t, i] = _logsumexp_top(terms, n_terms, top)
    log_alpha_in = np.ascontiguousarray(alpha_in.T)
    return log_alpha, log_alpha_in


@numba.njit(cache=True)
def backward(log_emission, log_transmat, log_duration, log_alpha, log_alpha_in, log_likelihood):
    """Backward variables and the expected transition and duration counts of one sequence.

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
    log_beta : array, shape (T, N)
        log p(xi_t+1..T-1 | a segment of state i ends at t).
    log_beta_in : array, shape (T, N)
        log p(xi_t..T-1 | a segment of state i starts at t).
    transition_counts : array, shape (N, N)
        Posterior expected number of transitions i -> j at [i, j].
    duration_counts : array, shape (N, n_durations)
        Posterior expected number of segments of state i lasting d steps.
    """
    n_steps, n_states = log_emission.shape
    n_durations = log_duration.shape[1]
    first, last = _support(log_duration)
    total = _cumulative(log_emission)
    beta = np.empty((n_states, n_steps))  # log_beta, state-major (see _cumulative)
    log_beta_in = np.empty((n_steps, n_states))
    transition_counts = np.zeros((n_states, n_states))
    duration_counts = np.zeros((n_states, n_durations))
    terms = np.empty(max(n_durations, n_states))
    for s in range(n_steps - 1, -1, -1):
        for i in range(n_states):
            if s == n_steps - 1:
                beta[i, s] = 0.0
                continue
            for j in range(n_states):
                terms[j] = log_transmat[i, j] + log_beta_in[s + 1, j]
            beta[i, s] = _logsumexp(terms, n_states)
            if beta[i, s] == _NEG_INF:
                continue
            # p(segment of i ends at s, one of j starts at s + 1 | all).
            scale = log_alpha[s, i] - log_likelihood
            for j in range(n_states):
                if terms[j] > beta[i, s] - _NEGLIGIBLE:
                    transition_counts[i, j] += np.exp(terms[j] + scale)
        for i in range(n_states):
            # Durations d = first + 1 .. min(last + 1, T - s); segment xi_{s..s+d-1}.
            low = first[i] + 1
            high = min(last[i] + 1, n_steps - s)
            top = _NEG_INF
            start = total[i, s]
            for d in range(low, high + 1):
                value = log_duration[i, d - 1] + total[i, s + d] - start + beta[i, s + d - 1]
                terms[d - low] = value
                top = max(top, value)
            if top == _NEG_INF:
                log_beta_in[s, i] = _NEG_INF
                continue
            weights = 0.0
            scale = np.exp(top + log_alpha_in[s, i] - log_likelihood)
            for d in range(low, high + 1):
                if terms[d - low] > top - _NEGLIGIBLE:
                    weight = np.exp(terms[d - low] - top)
                    weights += weight
                    duration_counts[i, d - 1] += weight * scale
            log_beta_in[s, i] = top + np.log(weights)
    log_beta = np.ascontiguousarray(beta.T)
    return log_beta, log_beta_in, transition_counts, duration_counts


@numba.njit(cache=True)
def residual_step(predicted, log_emission, transmat_T, durations):
    """One step of the residual-duration forward recursion (normalised).

    Parameters
    ----------
    predicted : array, shape (N, n_durations)
        p(state i, d steps left including this one | past), summing to 1.
    log_emission : array, shape (N,)
        log-likelihood of this step's observation per state (zeros: none).
    transmat_T : array, shape (N, N)
        Transposed transition matrix, a_ji at [i, j].
    durations : array, shape (N, n_durations)
        p_i(d).

    Returns
    -------
    h : array, shape (N,)
        p(state i active now | observations), summing to 1. If the
        observation is impossible under every state, the prediction alone.
    predicted_next : array, shape (N, n_durations)
    """
    n_states, n_durations = predicted.shape
    top = log_emission.max()
    weight = np.exp(log_emission - top)
    h = np.empty(n_states)
    for i in range(n_states):
        h[i] = weight[i] * predicted[i].sum()
    total = h.sum()
    if not total > 0:
        weight[:] = 1.0
        for i in range(n_states):
            h[i] = predicted[i].sum()
        total = h.sum()
    # Segments ending now (one step left) start the next states; the rest count down.
    starts = transmat_T @ (weight * predicted[:, 0])
    predicted_next = np.empty_like(predicted)
    for i in range(n_states):
        for d in range(n_durations - 1):
            predicted_next[i, d] = weight[i] * predicted[i, d + 1] + starts[i] * durations[i, d]
        predicted_next[i, n_durations - 1] = starts[i] * durations[i, n_durations - 1]
    return h / total, predicted_next / predicted_next.sum()


@numba.njit(cache=True)
def viterbi(log_emission, log_startprob, log_transmat, log_duration):
    """Segmental Viterbi: the most likely segmentation of one sequence.

    The max-product version of :func:`forward` (a complete segment ends the sequence).

    Parameters
    ----------
    log_emission, log_startprob, log_transmat, log_duration : arrays
        As for :func:`forward`.

    Returns
    -------
    log_probability : float
        log p(xi, best segmentation); -inf if no segmentation is possible.
    states : array of int, shape (T,)
        The state active at each step (all -1 if impossible).
    """
    n_steps, n_states = log_emission.shape
    first, last = _support(log_duration)
    total = _cumulative(log_emission)
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
def occupancy(log_alpha, log_alpha_in, log_beta, log_beta_in, log_likelihood):
    """p(state i active at t | all), shape (T, N), from the forward and backward variables.

    Segments of i started at or before t minus those ended before t, clipped to [0, 1]
    against round-off.
    """
    n_steps, n_states = log_alpha.shape
    gamma = np.empty((n_steps, n_states))
    for i in range(n_states):
        active = 0.0
        for t in range(n_steps):
            active += np.exp(log_alpha_in[t, i] + log_beta_in[t, i] - log_likelihood)
            if t > 0:
                active -= np.exp(log_alpha[t - 1, i] + log_beta[t - 1, i] - log_likelihood)
            gamma[t, i] = min(max(active, 0.0), 1.0)
    return gamma
