"""The HSMM's forward-backward kernels against a plain log-space recursion in numpy.

The kernels skip chunks of negligible terms; the reference sums every term with
np.logaddexp, so a chunk skipped wrongly (or a term lost far below the best) shows here.
"""

import numpy as np
import pytest

from hemg_drake.learning import _kernels, _segment_kernels


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
    return np.where(0.5 * z**2 <= _kernels._NEGLIGIBLE, log_p, -np.inf)


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
        np.full(3, -np.inf),
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
        np.full(2, -np.inf),
    )
    assert log_likelihood == -np.inf


def test_kept_terms_exp_within_two_ulp_of_numpy():
    import numba

    @numba.njit
    def evaluate(x):
        out = np.empty_like(x)
        for k in range(len(x)):
            out[k] = _kernels._exp_kept(x[k])
        return out

    rng = np.random.default_rng(3)
    x = np.concatenate([
        -rng.uniform(0.0, _kernels._NEGLIGIBLE, 200_000),
        [0.0, -1e-300, -1.0 / 128, -1.0 / 64, -np.nextafter(_kernels._NEGLIGIBLE, 0.0)],
    ])  # fmt: skip
    got, truth = evaluate(x), np.exp(x)
    assert np.max(np.abs(got - truth) / np.spacing(truth)) <= 2.0
    assert got[-5] == 1.0  # the largest term's weight is exactly 1
