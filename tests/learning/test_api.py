"""The estimator API that hmmlearn and scikit-learn users expect: params, lengths, score,
decode (against brute force), sample, information criteria, old files."""

import itertools
import json
import warnings

import numpy as np
import pytest
from scipy.stats import multivariate_normal, norm

from hemg_drake.learning.hsmm import HSMM, segments, select_n_states


def all_segmentations(n_steps, n_states, max_duration):
    """Every (states, durations) covering n_steps exactly, no self-transitions."""
    for n_segments in range(1, n_steps + 1):
        for durations in itertools.product(range(1, max_duration + 1), repeat=n_segments):
            if sum(durations) == n_steps:
                for states in itertools.product(range(n_states), repeat=n_segments):
                    if all(a != b for a, b in zip(states, states[1:])):
                        yield states, durations


def path_log_probabilities(model, demo):
    """log p(demo, segmentation) of every segmentation, from scipy densities."""
    n = model.n_states
    densities = [multivariate_normal(model.means_[i], model.covariances_[i]) for i in range(n)]
    log_b = np.stack([density.logpdf(demo) for density in densities], axis=1).reshape(-1, n)
    d = np.arange(1, model.max_duration_ + 1)
    log_d = norm.logpdf(d[None, :], model.duration_means_[:, None], model.duration_stds_[:, None])
    with np.errstate(divide="ignore"):
        log_pi, log_a = np.log(model.startprob_), np.log(model.transmat_)
    for states, durations in all_segmentations(len(demo), n, model.max_duration_):
        total, begin = log_pi[states[0]], 0
        for k, (state, duration) in enumerate(zip(states, durations)):
            if k:
                total += log_a[states[k - 1], state]
            total += log_d[state, duration - 1] + log_b[begin : begin + duration, state].sum()
            begin += duration
        yield total, np.repeat(states, durations)


@pytest.mark.parametrize("seed, n_states, n_steps, max_duration", [(0, 2, 6, 4), (1, 3, 6, 3),
                                                                   (2, 3, 7, 2)])
def test_decode_is_the_most_likely_segmentation(models, seed, n_states, n_steps, max_duration):
    rng = np.random.default_rng(seed)
    model = models.random_model(rng, n_states, 2, max_duration)
    demo = rng.standard_normal((n_steps, 2))
    paths = list(path_log_probabilities(model, demo))
    best_log_p, best_states = max(paths, key=lambda path: path[0])

    log_p, states = model.decode(demo)
    assert log_p == pytest.approx(best_log_p, rel=1e-10)
    np.testing.assert_array_equal(states, best_states)
    # Sum over the same paths: the likelihood that score gives.
    total = np.logaddexp.reduce([p for p, _ in paths])
    assert model.score(demo) == pytest.approx(total, rel=1e-10)


def test_decode_and_score_take_concatenated_sequences(models):
    rng = np.random.default_rng(3)
    model = models.random_model(rng, 3, 2, 4)
    a, b = rng.standard_normal((6, 2)), rng.standard_normal((5, 2))
    log_p, states = model.decode(np.vstack([a, b]), lengths=[6, 5])
    (log_a, states_a), (log_b, states_b) = model.decode(a), model.decode(b)
    assert log_p == pytest.approx(log_a + log_b, rel=1e-12)
    np.testing.assert_array_equal(states, np.concatenate([states_a, states_b]))
    assert model.score(np.vstack([a, b]), [6, 5]) == pytest.approx(
        model.log_likelihood(a) + model.log_likelihood(b), rel=1e-12
    )
    state, start, duration = segments(np.array([2, 2, 0, 1, 1, 1]))
    np.testing.assert_array_equal(np.stack([state, start, duration]), [[2, 0, 1], [0, 2, 3],
                                                                       [2, 1, 3]])


def test_fit_with_lengths_equals_fit_with_a_list(models):
    demos = models.smooth_demos(n_demos=3, n_steps=80, n_dims=4)
    listed = HSMM(3, n_iter=4, random_state=1).fit(demos)
    stacked = HSMM(3, n_iter=4, random_state=1).fit(np.vstack(demos), lengths=[len(d) for d in demos])
    np.testing.assert_array_equal(listed.means_, stacked.means_)
    assert listed.log_likelihood_history_ == stacked.log_likelihood_history_
    with pytest.raises(ValueError, match="lengths must be integers >= 1 summing to len"):
        HSMM(3).fit(np.vstack(demos), lengths=[80, 80])


def test_params_follow_the_scikit_learn_protocol():
    from sklearn.base import BaseEstimator, clone

    model = HSMM(4, reg_covar=1e-3, init="time", random_state=5)
    assert isinstance(model, BaseEstimator)
    params = model.get_params()
    assert params["n_states"] == 4 and params["reg_covar"] == 1e-3 and params["init"] == "time"
    assert params["random_state"] == 5 and "seed" not in params
    copy = clone(model)
    assert copy is not model and copy.get_params() == params
    assert copy.set_params(n_states=6, tol=0.0) is copy and copy.n_states == 6
    with pytest.raises(ValueError, match="Invalid parameter 'n_components'"):
        copy.set_params(n_components=3)
    # scikit-learn's convention: the constructor and set_params store, fit checks.
    copy.set_params(reg_covar=-1.0)
    with pytest.raises(ValueError, match="reg_covar must be > 0, got -1.0"):
        copy.fit(np.zeros((10, 2)))
    assert not hasattr(copy, "means_")
    assert repr(model) == "HSMM(init='time', n_states=4, random_state=5, reg_covar=0.001)"


def test_clone_of_a_fitted_model_is_unfitted(models):
    base = pytest.importorskip("sklearn.base")
    model = HSMM(2, n_iter=2).fit(models.smooth_demos(n_demos=2, n_steps=40, n_dims=4))
    with pytest.raises(ValueError, match="not fitted"):
        base.clone(model).score(np.zeros((5, 4)))


def known_model(models):
    """Two well separated states, 0 -> 1 -> 0, durations 5 and 12 steps."""
    return models.set_parameters(
        means=[[0.0, 0.0], [10.0, -5.0]],
        covariances=[np.eye(2), [[2.0, 0.5], [0.5, 1.0]]],
        startprob=[1.0, 0.0], transmat=[[0.0, 1.0], [1.0, 0.0]],
        duration_means=[5.0, 12.0], duration_stds=[1.0, 2.0], max_duration=30,
    )  # fmt: skip


def test_sample_follows_the_model(models):
    model = known_model(models)
    X, states = model.sample(20_000, random_state=4)
    again, _ = model.sample(20_000, random_state=4)
    np.testing.assert_array_equal(X, again)
    assert states[0] == 0 and X.shape == (20_000, 2)
    state, _, duration = segments(states)
    assert np.all(state[1:] != state[:-1])
    for i in range(2):
        runs = duration[:-1][state[:-1] == i]  # the last run is cut
        assert runs.mean() == pytest.approx(model.duration_means_[i], abs=0.1)
        assert runs.std() == pytest.approx(model.duration_stds_[i], rel=0.05)
        assert np.all(runs >= 1)
        np.testing.assert_allclose(X[states == i].mean(axis=0), model.means_[i], atol=0.05)
        np.testing.assert_allclose(np.cov(X[states == i].T), model.covariances_[i], atol=0.08)
    with pytest.raises(ValueError, match="n_samples must be an integer >= 1"):
        model.sample(0)


def test_information_criteria_count_the_free_parameters(models):
    model = known_model(models)
    X, _ = model.sample(195, random_state=1)
    # N = 2, D = 2: pi 1, A 0 (each row has one free entry), means 4, covariances 6, durations 4.
    assert model.n_parameters_ == 15
    log_l = model.score(X)
    assert model.bic(X) == pytest.approx(-2 * log_l + 15 * np.log(195), rel=1e-12)
    assert model.aic(X) == pytest.approx(-2 * log_l + 30, rel=1e-12)
    three = models.random_model(np.random.default_rng(0), 3, 2, 4)
    assert three.n_parameters_ == 2 + 3 + 6 + 9 + 6


def test_select_n_states_by_bic(models):
    rng = np.random.default_rng(6)
    model = known_model(models)
    demos = [model.sample(170, random_state=rng)[0] for _ in range(3)]
    best, scores = select_n_states(demos, [1, 2, 3], n_iter=10, init="kmeans")
    assert best.n_states == min(scores, key=scores.get) == 2
    assert set(scores) == {1, 2, 3}
    with pytest.raises(ValueError, match="criterion"):
        select_n_states(demos, [2], criterion="likelihood")


def test_models_written_before_the_new_defaults_still_load(models, tmp_path):
    model = HSMM(3, n_iter=2).fit(models.smooth_demos(n_demos=2, n_steps=60, n_dims=4))
    model.save(tmp_path / "new.npz")
    with np.load(tmp_path / "new.npz") as data:
        arrays = dict(data)
    old = json.loads(str(arrays["settings"]))
    old.update(min_duration_std=1.0, tol=1e-4)  # the defaults of format version 2 before
    old["seed"] = old.pop("random_state")  # the name before scikit-learn's random_state
    np.savez(tmp_path / "old.npz", **{**arrays, "settings": np.array(json.dumps(old))})
    loaded = HSMM.load(tmp_path / "old.npz")
    assert loaded.min_duration_std == 1.0 and loaded.tol == 1e-4
    assert loaded.random_state == model.random_state and "seed" not in loaded.get_params()
    np.testing.assert_array_equal(loaded.means_, model.means_)
    assert not any(isinstance(v, np.ndarray) and v.dtype == object for v in arrays.values())


def test_temporal_weighting_warns_where_the_timing_does_not_fix_the_states(models):
    chain = known_model(models)  # 0 -> 1 -> 0: visits both states, then cycles
    assert chain.state_order() == [0, 1]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        chain.check_weighting("temporal")
    left_to_right = models.set_parameters(
        means=np.zeros((3, 1)), covariances=np.ones((3, 1, 1)), startprob=[0.0, 1.0, 0.0],
        transmat=[[0, 0, 0], [0.05, 0, 0.95], [1, 0, 0]], duration_means=[5, 5, 5],
        duration_stds=[1, 1, 1], max_duration=20,
    )  # fmt: skip
    assert left_to_right.state_order() == [1, 2, 0]
    for startprob, transmat in [
        ([0.5, 0.5, 0.0], left_to_right.transmat_),  # two likely starts
        ([0.0, 1.0, 0.0], [[0, 0, 0], [0.4, 0, 0.6], [1, 0, 0]]),  # a branch
        ([0.0, 1.0, 0.0], [[0, 1, 0], [0, 0, 1], [0, 1, 0]]),  # 1 -> 2 -> 1, 0 never reached
    ]:
        left_to_right.startprob_ = np.array(startprob, float)
        left_to_right.transmat_ = np.array(transmat, float)
        assert left_to_right.state_order() is None
        with pytest.warns(UserWarning, match="temporal weighting follows the HSMM's timing"):
            left_to_right.check_weighting("temporal")
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            left_to_right.check_weighting("forward")


def test_the_worked_example_in_the_docs_runs(capsys):
    pytest.importorskip("sklearn")
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "learning.md").read_text()
    section = text[text.index("## As a library") :]
    code = section[section.index("```python\n") + 10 : section.index("```\n\nprints")]
    printed = section[section.index("prints\n\n```\n") + 12 :]
    exec(compile(code, "docs/learning.md", "exec"), {})
    assert capsys.readouterr().out == printed[: printed.index("```")]


def test_reproduce_warns_for_temporal_weighting_on_a_branching_model(models):
    from hemg_drake.learning.reproduce import reproduce

    branching = models.set_parameters(
        means=np.zeros((3, 2)), covariances=np.tile(np.eye(2), (3, 1, 1)),
        startprob=[0.0, 1.0, 0.0], transmat=[[0, 0, 0], [0.4, 0, 0.6], [1, 0, 0]],
        duration_means=[5, 5, 5], duration_stds=[1, 1, 1], max_duration=20, n_position=1,
    )  # fmt: skip
    for tracker in ("gmr", "lqr"):
        with pytest.warns(UserWarning, match="temporal weighting follows the HSMM's timing"):
            reproduce(branching, [0.0], 5, weighting="temporal", tracker=tracker)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            reproduce(branching, [0.0], 5, weighting="forward", tracker=tracker)
