"""The HSMM's forward-backward kernels against a plain log-space recursion in numpy.

The kernels skip chunks of negligible terms; the reference sums every term with
np.logaddexp, so a chunk skipped wrongly (or a term lost far below the best) shows here.
"""

import hashlib
from pathlib import Path

import numpy as np
import pytest

from hemg_drake.learning import _bound_kernels, _kernels, _segment_kernels, _sum_kernels


def logsumexp(values, axis=None):
    return np.logaddexp.reduce(values, axis=axis)


def reference(log_emission, log_startprob, log_transmat, log_duration):
    """log-likelihood, occupancy, transition and duration counts, every term summed."""
    n_steps, n_states = log_emission.shape
    n_durations = log_duration.shape[1]
    cumulative = np.vstack([np.zeros(n_states), np.cumsum(log_emission, axis=0)])
    log_alpha = np.full((n_steps, n_states), -np.inf)
    log_alpha_in = np.full((n_steps, n_states), -np.inf)
    for t in range(n_steps):
        log_alpha_in[t] = log_startprob if t == 0 else logsumexp(
            log_alpha[t - 1][:, None] + log_transmat, axis=0
        )
        d = np.arange(1, min(n_durations, t + 1) + 1)
        begin = t - d + 1
        terms = (log_alpha_in[begin] + log_duration[:, d - 1].T
                 + cumulative[t + 1] - cumulative[begin])  # fmt: skip
        log_alpha[t] = logsumexp(terms, axis=0)
    log_likelihood = logsumexp(log_alpha[-1])
    log_beta = np.zeros((n_steps, n_states))
    log_beta_in = np.full((n_steps, n_states), -np.inf)
    durations = np.zeros((n_states, n_durations))
    for s in range(n_steps - 1, -1, -1):
        if s < n_steps - 1:
            log_beta[s] = logsumexp(log_transmat + log_beta_in[s + 1][None, :], axis=1)
        d = np.arange(1, min(n_durations, n_steps - s) + 1)
        terms = (log_duration[:, d - 1].T + cumulative[s + d] - cumulative[s]
                 + log_beta[s + d - 1])  # fmt: skip
        log_beta_in[s] = logsumexp(terms, axis=0)
        durations[:, d - 1] += np.exp(terms + log_alpha_in[s] - log_likelihood).T
    transitions = np.exp(
        log_alpha[:-1, :, None] + log_transmat[None] + log_beta_in[1:, None, :] - log_likelihood
    ).sum(axis=0)
    starts = np.exp(log_alpha_in + log_beta_in - log_likelihood)
    ends = np.exp(log_alpha + log_beta - log_likelihood)
    gamma = np.cumsum(starts, axis=0) - np.vstack([np.zeros(n_states), np.cumsum(ends, axis=0)[:-1]])
    return log_likelihood, np.clip(gamma, 0.0, 1.0), transitions, durations


def log_durations(means, stds, n_durations):
    d = np.arange(1, n_durations + 1)
    z = (d[None, :] - means[:, None]) / stds[:, None]
    log_p = -0.5 * z**2 - np.log(np.sqrt(2.0 * np.pi) * stds)[:, None]
    return np.where(0.5 * z**2 <= _sum_kernels.NEGLIGIBLE, log_p, -np.inf)


def kernels(log_emission, log_startprob, log_transmat, log_duration):
    log_alpha, log_alpha_in = _kernels.forward(
        log_emission, log_startprob, log_transmat, log_duration
    )
    log_likelihood = logsumexp(log_alpha[-1])
    *_, transitions, durations, starts, ends = _kernels.backward(
        log_emission, log_transmat, log_duration, log_alpha, log_alpha_in, log_likelihood
    )
    gamma = _segment_kernels.occupancy(starts, ends, np.array([0, len(starts)]))
    return log_likelihood, gamma, transitions, durations


def steep_case(left_to_right, wide, seed):
    """States that each fit one stretch of the sequence, hundreds of nats apart elsewhere."""
    rng = np.random.default_rng(seed)
    n_states, n_steps = 5, 400
    phase = np.minimum(np.arange(n_steps) * n_states // n_steps, n_states - 1)
    distance = np.abs(np.arange(n_states)[None, :] - phase[:, None])
    log_emission = -300.0 * distance + rng.normal(0.0, 2.0, (n_steps, n_states))
    if left_to_right:
        transmat = np.eye(n_states, k=1)
        startprob = np.eye(n_states)[0]
    else:
        transmat = rng.uniform(0.05, 1.0, (n_states, n_states))
        np.fill_diagonal(transmat, 0.0)
        transmat /= transmat.sum(axis=1, keepdims=True)
        startprob = rng.dirichlet(np.ones(n_states))
    stds = np.full(n_states, 40.0 if wide else 3.0)
    log_duration = log_durations(rng.uniform(60.0, 100.0, n_states), stds, 300)
    with np.errstate(divide="ignore"):
        return log_emission, np.log(startprob), np.log(transmat), log_duration


@pytest.mark.parametrize("left_to_right", [True, False])
@pytest.mark.parametrize("wide", [True, False])
def test_kernels_equal_every_term_summed(left_to_right, wide):
    case = steep_case(left_to_right, wide, seed=int(left_to_right) + 2 * int(wide))
    expected = reference(*case)
    got = kernels(*case)
    assert np.isfinite(got[0])
    assert got[0] == pytest.approx(expected[0], rel=1e-12)
    for value, truth in zip(got[1:], expected[1:]):
        np.testing.assert_allclose(value, truth, rtol=1e-9, atol=1e-10)


def test_kernels_equal_every_term_summed_on_random_models():
    rng = np.random.default_rng(5)
    for _ in range(5):
        n_states, n_steps, n_durations = rng.integers(2, 6), rng.integers(20, 200), 40
        log_emission = rng.normal(0.0, 30.0, (n_steps, n_states))
        transmat = rng.uniform(0.0, 1.0, (n_states, n_states))
        np.fill_diagonal(transmat, 0.0)
        transmat /= transmat.sum(axis=1, keepdims=True)
        log_duration = log_durations(
            rng.uniform(1.0, 30.0, n_states), rng.uniform(0.5, 8.0, n_states), n_durations
        )
        with np.errstate(divide="ignore"):
            case = (log_emission, np.log(rng.dirichlet(np.ones(n_states))), np.log(transmat),
                    log_duration)  # fmt: skip
            expected = reference(*case)
        got = kernels(*case)
        assert got[0] == pytest.approx(expected[0], rel=1e-12)
        for value, truth in zip(got[1:], expected[1:]):
            np.testing.assert_allclose(value, truth, rtol=1e-9, atol=1e-10)


def test_expectation_over_concatenated_sequences_equals_each_summed():
    # Three sequences of different lengths in one call: the log-likelihoods and counts are
    # the every-term reference's of each, added up; gamma is each one's, in place.
    rng = np.random.default_rng(11)
    n_states, n_durations = 4, 40
    transmat = rng.uniform(0.05, 1.0, (n_states, n_states))
    np.fill_diagonal(transmat, 0.0)
    transmat /= transmat.sum(axis=1, keepdims=True)
    log_duration = log_durations(
        rng.uniform(5.0, 20.0, n_states), rng.uniform(1.0, 5.0, n_states), n_durations
    )
    with np.errstate(divide="ignore"):
        log_transmat = np.log(transmat)
    log_startprob = np.log(rng.dirichlet(np.ones(n_states)))
    emissions = [rng.normal(0.0, 30.0, (n_steps, n_states)) for n_steps in (50, 120, 81)]
    bounds = np.array([0, 50, 170, 251])
    log_likelihood, sequences, starts, ends, transitions, durations = _kernels.expectation(
        np.concatenate(emissions), bounds, log_startprob, log_transmat, log_duration,
        np.full(3, -np.inf), *_bound_kernels.suffix_bound(
            np.concatenate(emissions), bounds, log_transmat, log_duration),
    )
    gamma = _segment_kernels.occupancy(starts, ends, bounds)
    starts = starts[bounds[:-1]].sum(axis=0)
    expected = [reference(e, log_startprob, log_transmat, log_duration) for e in emissions]
    assert log_likelihood == pytest.approx(sum(r[0] for r in expected), rel=1e-12)
    np.testing.assert_allclose(gamma, np.concatenate([r[1] for r in expected]), atol=1e-10)
    np.testing.assert_allclose(transitions, sum(r[2] for r in expected), rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(durations, sum(r[3] for r in expected), rtol=1e-9, atol=1e-10)
    # Each sequence's first-segment posterior is its occupancy at its first step.
    np.testing.assert_allclose(starts, sum(r[1][0] for r in expected), atol=1e-10)


def test_expectation_stops_at_an_impossible_sequence():
    log_duration = np.full((2, 3), -np.inf)
    log_duration[:, 2] = 0.0  # every segment lasts exactly 3 steps
    log_transmat = np.log(np.array([[0.5, 0.5], [0.5, 0.5]]))
    log_startprob = np.log(np.full(2, 0.5))
    # 6 steps then 4: the second cannot end with a complete segment.
    log_likelihood, *_ = _kernels.expectation(
        np.zeros((10, 2)), np.array([0, 6, 10]), log_startprob, log_transmat, log_duration,
        np.full(2, 5.0), *_bound_kernels.suffix_bound(
            np.zeros((10, 2)), np.array([0, 6, 10]), log_transmat, log_duration),
    )
    assert log_likelihood == -np.inf


def test_kept_terms_exp_within_two_ulp_of_numpy():
    import numba

    @numba.njit
    def evaluate(x):
        out = np.empty_like(x)
        for k in range(len(x)):
            out[k] = _sum_kernels.exp_kept(x[k])
        return out

    rng = np.random.default_rng(3)
    x = np.concatenate([
        -rng.uniform(0.0, _sum_kernels.NEGLIGIBLE, 200_000),
        [0.0, -1e-300, -1.0 / 128, -1.0 / 64, -np.nextafter(_sum_kernels.NEGLIGIBLE, 0.0)],
    ])  # fmt: skip
    got, truth = evaluate(x), np.exp(x)
    assert np.max(np.abs(got - truth) / np.spacing(truth)) <= 2.0
    assert got[-5] == 1.0  # the largest term's weight is exactly 1


def brute_force(log_emission, log_startprob, log_transmat, log_duration):
    """log-likelihood, occupancy, first-segment, transition and duration posteriors of a
    small model by listing every segmentation (state, duration)* of the sequence."""
    n_steps, n_states = log_emission.shape
    n_durations = log_duration.shape[1]
    paths = []  # (log joint, [(state, start, duration), ...])

    def extend(segments, score, t):
        if t == n_steps:
            paths.append((score, segments))
            return
        for i in range(n_states):
            enter = log_startprob[i] if t == 0 else log_transmat[segments[-1][0], i]
            for d in range(1, min(n_durations, n_steps - t) + 1):
                value = score + enter + log_duration[i, d - 1] + log_emission[t : t + d, i].sum()
                if value > -np.inf:
                    extend(segments + [(i, t, d)], value, t + d)

    extend([], 0.0, 0)
    scores = np.array([score for score, _ in paths])
    log_likelihood = logsumexp(scores)
    gamma = np.zeros((n_steps, n_states))
    starts = np.zeros(n_states)
    transitions = np.zeros((n_states, n_states))
    durations = np.zeros((n_states, n_durations))
    for score, segments in paths:
        weight = np.exp(score - log_likelihood)
        starts[segments[0][0]] += weight
        for (i, t, d), following in zip(segments, segments[1:] + [None]):
            gamma[t : t + d, i] += weight
            durations[i, d - 1] += weight
            if following is not None:
                transitions[i, following[0]] += weight
    return log_likelihood, gamma, starts, transitions, durations


@pytest.mark.parametrize("steep", [False, True])
def test_pruned_expectation_equals_every_segmentation_listed(steep):
    # Left-to-right with a skip (zeros in A, which the sums leave out), narrow duration
    # windows (-inf outside), and, when steep, states hundreds of nats apart per step, so
    # that the E-step given its own log-likelihood as the guess leaves out segment starts
    # and ends (checked on the forward pass): it must still equal the full listing.
    rng = np.random.default_rng(int(steep))
    n_states, n_steps = 3, 9
    phase = np.minimum(np.arange(n_steps) * n_states // n_steps, n_states - 1)
    spread = 400.0 if steep else 1.0
    log_emission = -spread * np.abs(np.arange(n_states)[None, :] - phase[:, None]) + rng.normal(
        0.0, 1.0, (n_steps, n_states))
    transmat = np.array([[0.0, 0.7, 0.3], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    log_duration = np.full((n_states, 6), -np.inf)
    log_duration[0, 1:5] = np.log([0.1, 0.4, 0.4, 0.1])
    log_duration[1, 1:4] = np.log([0.3, 0.4, 0.3])
    log_duration[2, 0:6] = np.log([0.05, 0.15, 0.3, 0.3, 0.15, 0.05])
    with np.errstate(divide="ignore"):
        case = (log_emission, np.log([0.8, 0.2, 0.0]), np.log(transmat), log_duration)
    expected = brute_force(*case)
    bounds = np.array([0, n_steps])
    for guesses in (np.full(1, -np.inf), np.full(1, expected[0]), np.full(1, expected[0] + 5.0)):
        log_likelihood, sequences, starts, ends, transitions, durations = _kernels.expectation(
            *case[:1], bounds, *case[1:], guesses,
            *_bound_kernels.suffix_bound(case[0], bounds, *case[2:]),
        )
        assert log_likelihood == pytest.approx(expected[0], rel=1e-12)
        assert sequences[0] == log_likelihood
        gamma = _segment_kernels.occupancy(starts, ends, bounds)
        np.testing.assert_allclose(gamma, expected[1], atol=1e-12)
        np.testing.assert_allclose(starts[0], expected[2], atol=1e-12)
        np.testing.assert_allclose(transitions, expected[3], atol=1e-12)
        np.testing.assert_allclose(durations, expected[4], atol=1e-12)
    if steep:  # the bound leaves some out at the likelihood's own floor
        floor = expected[0] - _kernels.UNDERFLOW - np.log(2.0 * log_emission.size)
        full = _kernels.forward(*case)
        suffix = _bound_kernels.suffix_bound(case[0], bounds, *case[2:])
        pruned = _kernels.forward_pruned(*case, floor, suffix)
        assert np.sum(np.isfinite(pruned[1])) < np.sum(np.isfinite(full[1]))


def test_suffix_bound_is_above_every_backward_value():
    # The pruning is exact only if the bound is one: on random models (sparse A, duration
    # weights summing to more than 1 for narrow spreads) it must be at least log beta_in
    # and log beta of the full passes everywhere, and reached where only one path is left.
    rng = np.random.default_rng(7)
    for trial in range(6):
        n_states, n_steps = 4, 40
        log_emission = rng.normal(0.0, 20.0, (n_steps, n_states))
        transmat = rng.uniform(0.0, 1.0, (n_states, n_states)) * (rng.random((4, 4)) < 0.6)
        np.fill_diagonal(transmat, 0.0)
        transmat[np.arange(n_states), (np.arange(n_states) + 1) % n_states] += 0.1
        transmat /= transmat.sum(axis=1, keepdims=True)
        stds = rng.uniform(0.3, 4.0, n_states) if trial % 2 else np.full(n_states, 0.3)
        log_duration = log_durations(rng.uniform(2.0, 10.0, n_states), stds, 20)
        with np.errstate(divide="ignore"):
            case = (log_emission, np.log(np.full(n_states, 0.25)), np.log(transmat), log_duration)
        log_alpha, log_alpha_in = _kernels.forward(*case)
        log_likelihood = logsumexp(log_alpha[-1])
        log_beta, log_beta_in, *_ = _kernels.backward(
            log_emission, case[2], log_duration, log_alpha, log_alpha_in, log_likelihood
        )
        starts, ends = _bound_kernels.suffix_bound(
            log_emission, np.array([0, n_steps]), case[2], log_duration)
        assert np.all(log_beta_in <= starts + 1e-9)
        assert np.all(log_beta <= ends + 1e-9)
        # The last step: a segment of one step ending the sequence, weighted p_i(1) <= S.
        assert np.all(ends[-1] == 0.0)


def test_recursions_are_cached_against_the_sum_kernels_they_compile_in():
    """numba's cache does not see _sum_kernels.py change under _kernels.py's functions, which
    inline it: _kernels caches only against the pinned digest of that file (update it)."""
    source = Path(_sum_kernels.__file__).read_bytes().replace(b"\r\n", b"\n")
    assert hashlib.sha256(source).hexdigest() == _kernels.SUM_KERNELS_SHA256
