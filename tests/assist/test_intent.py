"""The intent estimator against a brute-force forward recursion and closed-form confidences."""

import itertools

import numpy as np
import pytest

from hemg_drake.assist.intent import IntentEstimator
from hemg_drake.learning.hsmm import HSMM


def hand_model(*, means, variances, startprob, transmat, duration_means, duration_stds,
               max_duration):
    """A 1-D position HSMM ([x, xdot]) with the given parameters, as if fitted."""
    n = len(means)
    model = HSMM(n, max_duration=max_duration, n_position=1)
    model.means_ = np.column_stack([means, np.zeros(n)]).astype(float)
    model.covariances_ = np.array([np.diag([v, 1.0]) for v in variances])
    model.startprob_ = np.asarray(startprob, dtype=float)
    model.transmat_ = np.asarray(transmat, dtype=float)
    model.duration_means_ = np.asarray(duration_means, dtype=float)
    model.duration_stds_ = np.asarray(duration_stds, dtype=float)
    model.occupancy_ = np.full(n, 1.0 / n)
    model.data_range_ = np.outer([-1.0, 1.0], np.ones(2))
    model.max_duration_ = max_duration
    model.log_likelihood_history_ = []
    return model


def brute_force_filter(model, observations):
    """p(state at t | x_0..x_t) for each t by summing every segmentation explicitly.

    A path is segments (s_k, d_k): s_1 ~ pi, s_k ~ a_{s_{k-1}} (a final state, with no way
    out, repeats itself), d_k ~ p_{s_k}(d); its weight is the product of those and of
    N(x_tau | s(tau)) for tau <= t, over the paths whose last segment covers t.
    """
    n, d_max = model.n_states, model.max_duration_
    durations = np.exp(model.log_durations())
    transmat = model.transmat_.copy()
    final = transmat.sum(axis=1) == 0
    transmat[final, final] = 1.0
    means, variances = model.means_[:, 0], model.covariances_[:, 0, 0]

    def density(x):
        return np.exp(-0.5 * (x - means) ** 2 / variances) / np.sqrt(2 * np.pi * variances)

    emissions = np.array([density(x) for x in observations])
    results = []
    for t in range(len(observations)):
        h = np.zeros(n)
        # Every sequence of segment lengths whose sum first reaches past t.
        for count in range(1, t + 2):
            for lengths in itertools.product(range(1, d_max + 1), repeat=count):
                if not sum(lengths[:-1]) <= t < sum(lengths):
                    continue
                for states in itertools.product(range(n), repeat=count):
                    weight = model.startprob_[states[0]]
                    for k, (s, d) in enumerate(zip(states, lengths)):
                        if k:
                            weight *= transmat[states[k - 1], s]
                        weight *= durations[s, d - 1]
                    timeline = np.repeat(states, lengths)[: t + 1]
                    weight *= np.prod(emissions[np.arange(t + 1), timeline])
                    h[states[-1]] += weight
        results.append(h / h.sum())
    return np.array(results)


def run_estimator(model, observations, dt=0.01, tau=0.2):
    """(h, confidence, next_target) of the IntentEstimator after each observation."""
    system = IntentEstimator(model=model, dt=dt, likelihood_time_constant=tau)
    context = system.CreateDefaultContext()
    rows = []
    for x in observations:
        system.get_input_port().FixValue(context, np.atleast_1d(x))
        update = system.EvalUniquePeriodicDiscreteUpdate(context)
        context.SetDiscreteState(update)
        rows.append((
            system.GetOutputPort("h").Eval(context).copy(),
            system.GetOutputPort("confidence").Eval(context)[0],
            system.GetOutputPort("next_target").Eval(context).copy(),
        ))  # fmt: skip
    return rows


def three_states():
    return hand_model(
        means=[0.0, 1.0, 2.0], variances=[0.3, 0.2, 0.4], startprob=[0.7, 0.2, 0.1],
        transmat=[[0.0, 0.8, 0.2], [0.1, 0.0, 0.9], [0.0, 0.0, 0.0]],
        duration_means=[2.0, 1.5, 2.5], duration_stds=[0.8, 0.6, 1.0], max_duration=3,
    )  # fmt: skip


def test_forward_variable_matches_brute_force():
    model = three_states()
    observations = [0.1, -0.2, 0.9, 1.2, 1.9, 0.4, 2.2]
    expected = brute_force_filter(model, observations)
    rows = run_estimator(model, observations)
    got = np.array([h for h, _, _ in rows])
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)


def test_next_target_is_the_mean_of_the_state_entered_next():
    model = three_states()
    rows = run_estimator(model, [0.0, 0.05])
    h = rows[-1][0]
    assert np.argmax(h) == 0  # state 0's successors: 1 (0.8) before 2 (0.2)
    assert rows[-1][2][0] == 1.0
    rows = run_estimator(model, [2.0, 2.1, 1.9])
    assert np.argmax(rows[-1][0]) == 2  # the final state repeats itself
    assert rows[-1][2][0] == 2.0


@pytest.mark.parametrize("offset_sigmas", [0.0, 1.0, 3.0])
def test_confidence_of_one_state_is_the_likelihood_in_closed_form(offset_sigmas):
    """N = 1 (certainty 1), tau = dt (no averaging): kappa = exp(min(0, (1 - z^2) / 2)),
    z the sample's distance from the mean in sigmas (P = 1)."""
    model = hand_model(
        means=[0.5], variances=[0.04], startprob=[1.0], transmat=[[0.0]],
        duration_means=[2.0], duration_stds=[1.0], max_duration=4,
    )  # fmt: skip
    x = 0.5 + offset_sigmas * 0.2
    _, confidence, _ = run_estimator(model, [x], dt=0.01, tau=0.01)[0]
    assert confidence == pytest.approx(np.exp(min(0.0, (1.0 - offset_sigmas**2) / 2.0)))


def test_confidence_of_an_undecided_belief_is_zero_and_of_a_sure_one_is_one():
    """Two states with the same emission and a 50/50 start: entropy log 2, kappa 0. A
    single observation at one of two far-apart means: certainty 1, and the prediction gave
    it 1/2, so r = log(1/2) + P/2 (P = 1) and kappa = exp(beta r / P), beta = dt / tau."""
    same = hand_model(
        means=[0.0, 0.0], variances=[1.0, 1.0], startprob=[0.5, 0.5],
        transmat=[[0.0, 1.0], [1.0, 0.0]], duration_means=[3.0, 3.0],
        duration_stds=[0.5, 0.5], max_duration=4,
    )  # fmt: skip
    assert run_estimator(same, [0.0])[0][1] == pytest.approx(0.0, abs=1e-12)
    apart = hand_model(
        means=[0.0, 100.0], variances=[1.0, 1.0], startprob=[0.5, 0.5],
        transmat=[[0.0, 1.0], [1.0, 0.0]], duration_means=[3.0, 3.0],
        duration_stds=[0.5, 0.5], max_duration=4,
    )  # fmt: skip
    beta = 0.01 / 0.2
    expected = np.exp(beta * (0.5 - np.log(2.0)))
    assert run_estimator(apart, [100.0])[0][1] == pytest.approx(expected, rel=1e-12)


def test_the_estimator_clones_in_a_diagram():
    """Clone() of a diagram holding it (double -> AutoDiffXd -> double): the same outputs."""
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource([1.1]))
    estimator = builder.AddNamedSystem("intent", IntentEstimator(model=three_states(), dt=0.01))
    builder.Connect(source.get_output_port(), estimator.get_input_port())
    builder.ExportOutput(estimator.GetOutputPort("confidence"), "confidence")
    diagram = builder.Build()
    values = []
    for system in (diagram, diagram.Clone()):
        from pydrake.systems.analysis import Simulator

        simulator = Simulator(system)
        simulator.AdvanceTo(0.1)
        values.append(system.get_output_port().Eval(simulator.get_context())[0])
    assert values[0] == values[1] and 0.0 < values[0] <= 1.0


def test_forward_step_survives_an_observation_that_underflows_the_prediction():
    """The assist's policy observes a tool far from every state (a noisy operator at 250 ms
    gave NaN weights, measured): an observation whose weight underflows the next prediction
    to zero is ignored, the prediction alone (by hand: state 0 holds all the mass)."""
    from hemg_drake.learning._step_kernels import residual_step

    # exp(-745) is the smallest subnormal: times 0.3 or 0.4 it rounds to 0.
    predicted = np.array([[0.0, 0.3, 0.3, 0.4], [0.0, 0.0, 0.0, 0.0]])
    transmat_T = np.array([[0.0, 0.0], [1.0, 0.0]])
    durations = np.full((2, 4), 0.25)
    h, predicted_next = residual_step(predicted, np.array([-745.0, 0.0]), transmat_T, durations)
    assert np.all(np.isfinite(h)) and np.all(np.isfinite(predicted_next))
    np.testing.assert_array_equal(h, [1.0, 0.0])
    np.testing.assert_allclose(predicted_next, [[0.3, 0.3, 0.4, 0.0], [0.0] * 4], rtol=1e-15)
