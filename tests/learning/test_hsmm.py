"""HSMM: forward variable against brute force, EM, recovery, persistence, bad input."""

import itertools

import numpy as np
import pytest
from scipy.stats import multivariate_normal, norm

from hemg_drake.learning.hsmm import HSMM, polyline_segments, segments


def segmentations(n_steps, n_states, max_duration):
    """Every (states, durations) path covering exactly n_steps, no self-transitions."""
    for n_segments in range(1, n_steps + 1):
        for durations in itertools.product(range(1, max_duration + 1), repeat=n_segments):
            if sum(durations) != n_steps:
                continue
            for states in itertools.product(range(n_states), repeat=n_segments):
                if all(a != b for a, b in zip(states, states[1:])):
                    yield states, durations


def brute_force(model, demo, observe):
    """alpha (segment of i ends at t) and occupancy (i active at t), summed over all paths.

    Independent of the package: scipy densities, explicit products over paths.
    """
    n_steps, n = len(demo), model.n_states
    d_max = model.max_duration_
    emission = np.ones((n_steps, n))
    if observe:
        for i in range(n):
            emission[:, i] = multivariate_normal(model.means_[i], model.covariances_[i]).pdf(demo)
    p_d = norm.pdf(np.arange(1, d_max + 1)[None, :], model.duration_means_[:, None],
                   model.duration_stds_[:, None])
    survival = np.cumsum(p_d[:, ::-1], axis=1)[:, ::-1]  # sum over d' >= d
    alpha = np.zeros((n_steps, n))
    occupancy = np.zeros((n_steps, n))
    for t in range(n_steps):
        for states, durations in segmentations(t + 1, n, d_max):
            weight = model.startprob_[states[0]]
            for k, (state, duration) in enumerate(zip(states, durations)):
                if k:
                    weight *= model.transmat_[states[k - 1], state]
                begin = sum(durations[:k])
                weight *= np.prod(emission[begin:begin + duration, state])
            last = states[-1]
            before = np.prod([p_d[s, d - 1] for s, d in zip(states[:-1], durations[:-1])])
            alpha[t, last] += weight * before * p_d[last, durations[-1] - 1]
            occupancy[t, last] += weight * before * survival[last, durations[-1] - 1]
    return alpha, occupancy / occupancy.sum(axis=1, keepdims=True)


@pytest.mark.parametrize("n_states, n_steps, max_duration", [(2, 6, 6), (3, 6, 3), (3, 5, 2)])
@pytest.mark.parametrize("observe", [True, False])
def test_forward_variable_equals_brute_force(models, n_states, n_steps, max_duration, observe):
    rng = np.random.default_rng(n_states * 10 + n_steps)
    model = models.random_model(rng, n_states, 2, max_duration)
    demo = rng.standard_normal((n_steps, 2))
    alpha, occupancy = brute_force(model, demo, observe)

    given = demo if observe else n_steps
    np.testing.assert_allclose(
        np.exp(model.log_forward_variable(given, observe=observe)), alpha, rtol=1e-10, atol=0
    )
    np.testing.assert_allclose(
        model.forward_variable(given, observe=observe), occupancy, rtol=1e-10, atol=1e-300
    )
    if observe:
        assert model.log_likelihood(demo) == pytest.approx(np.log(alpha[-1].sum()), rel=1e-10)


def seeded_truth():
    """A 3-state HSMM over [x, y, xdot, ydot]; states differ in position."""
    transmat = np.array([[0.0, 0.8, 0.2], [0.3, 0.0, 0.7], [0.6, 0.4, 0.0]])
    position_cov = np.array(
        [[[0.3, 0.1], [0.1, 0.2]], 0.2 * np.eye(2), [[0.2, -0.05], [-0.05, 0.3]]]
    )
    covariances = np.zeros((3, 4, 4))
    covariances[:, :2, :2] = position_cov
    covariances[:, 2:, 2:] = 0.5 * np.eye(2)
    covariances[:, 0, 2] = covariances[:, 2, 0] = 0.1  # x and xdot correlate
    return dict(
        means=np.array([[0.0, 0.0, 1.0, 0.0], [3.0, 0.0, 0.0, 1.0], [0.0, 3.0, -1.0, -1.0]]),
        covariances=covariances,
        startprob=np.array([1.0, 0.0, 0.0]),
        transmat=transmat,
        duration_means=np.array([12.0, 20.0, 8.0]),
        duration_stds=np.array([2.0, 3.0, 1.5]),
    )


def test_em_recovers_a_known_hsmm(models):
    truth = seeded_truth()
    rng = np.random.default_rng(1)
    data = [models.sample(rng, **truth, n_segments=12) for _ in range(4)]
    demos = [observations for observations, _ in data]
    model = HSMM(3, max_duration=50, n_iter=30, random_state=3).fit(demos)

    # Match fitted states to true ones by their means.
    order = [np.argmin(np.linalg.norm(model.means_ - mu, axis=1)) for mu in truth["means"]]
    assert sorted(order) == [0, 1, 2]
    np.testing.assert_allclose(model.means_[order], truth["means"], atol=0.15)
    # Durations, against the runs of the true states in these demos (the sampler's own
    # segmentation): EM's duration M-step gives their weighted mean and spread, so with the
    # states this well separated its estimates sit within 0.1 step and 3 % of them (measured:
    # 0.03 step, 1 %). Tight enough that a mean off by one step, the variance reported as
    # the std, or a sign error in the spread's update each fail (tried: each goes red).
    runs = [[] for _ in truth["means"]]
    for _, true_states in data:
        state, _, duration = segments(true_states)
        for i, d in zip(state, duration):
            runs[i].append(d)
    run_means = np.array([np.mean(r) for r in runs])
    run_stds = np.array([np.std(r) for r in runs])
    assert np.all(run_stds > 1.1)  # the variance differs from the std by at least 10 %
    np.testing.assert_allclose(model.duration_means_[order], run_means, atol=0.1)
    np.testing.assert_allclose(model.duration_stds_[order], run_stds, rtol=0.03)
    # And the truth, to its sampling error (16 runs a state: sigma / 4 on the mean).
    np.testing.assert_allclose(model.duration_means_[order], truth["duration_means"], atol=0.7)
    np.testing.assert_allclose(model.duration_stds_[order], truth["duration_stds"], rtol=0.25)
    np.testing.assert_allclose(model.transmat_[np.ix_(order, order)], truth["transmat"], atol=0.15)
    np.testing.assert_array_equal(np.diag(model.transmat_), 0.0)
    states = np.asarray(order)[data[0][1]]
    assert np.mean(model.predict_states(demos[0]) == states) > 0.97


@pytest.mark.parametrize("init", ["kmeans", "time"])
def test_em_log_likelihood_never_decreases(models, init):
    truth = seeded_truth()
    rng = np.random.default_rng(2)
    demos = [models.sample(rng, **truth, n_segments=8)[0] for _ in range(3)]
    model = HSMM(4, n_iter=15, tol=0.0, init=init, random_state=0).fit(demos)
    history = np.asarray(model.log_likelihood_history_)
    assert len(history) == 15
    assert np.all(np.diff(history) >= -1e-9 * np.abs(history[1:]))
    assert history[-1] > history[0]  # it did learn something


def test_fit_is_deterministic_for_a_seed(models):
    demos = models.smooth_demos(n_demos=2, n_steps=120, n_dims=3)
    first = HSMM(4, n_iter=3, random_state=7).fit(demos)
    second = HSMM(4, n_iter=3, random_state=7).fit(demos)
    np.testing.assert_array_equal(first.means_, second.means_)
    assert first.log_likelihood_history_ == second.log_likelihood_history_


def test_long_sequences_do_not_underflow(models):
    truth = seeded_truth()
    demo, _ = models.sample(np.random.default_rng(4), **truth, n_segments=800)
    assert len(demo) > 10_000
    model = models.set_parameters(**truth, max_duration=40)
    log_likelihood = model.log_likelihood(demo)
    # Per step, close to the expected emission log-density of the data (about -3.3 nats).
    assert np.isfinite(log_likelihood) and -5.0 < log_likelihood / len(demo) < -2.0
    h = model.forward_variable(demo)
    assert np.all(np.isfinite(h)) and np.allclose(h.sum(axis=1), 1.0)


def test_default_duration_limits_follow_the_initial_segmentation(models):
    demos = models.smooth_demos(n_demos=2, n_steps=2000, n_dims=3)
    model = HSMM(5, n_iter=1, init="time").fit(demos)
    # init="time" cuts demo c into 5 equal runs: lengths 400 (demo 0) and 404 (demo 1).
    runs = np.array([400.0] * 5 + [404.0] * 5)
    assert model.min_duration_std_ == pytest.approx(0.02 * runs.mean())
    spread = max(runs.std(), 0.02 * runs.mean(), 0.25 * runs.mean())
    assert model.max_duration_ == int(np.ceil(runs.mean() + 4 * spread))
    # A given value wins; d_max never exceeds the longest demonstration.
    assert HSMM(5, n_iter=1, max_duration=333, min_duration_std=2.0).fit(demos).max_duration_ == 333
    assert HSMM(1, n_iter=1, init="time").fit(demos[:1]).max_duration_ == len(demos[0])


def test_duration_support_is_ten_spreads_around_the_mean(models):
    model = models.set_parameters(
        means=np.zeros((2, 1)), covariances=np.ones((2, 1, 1)), startprob=[1.0, 0.0],
        transmat=[[0.0, 1.0], [1.0, 0.0]], duration_means=[50.0, 10.0],
        duration_stds=[2.0, 1.0], max_duration=100,
    )  # fmt: skip
    finite = np.isfinite(model.log_durations())
    d = np.arange(1, 101)
    np.testing.assert_array_equal(finite[0], np.abs(d - 50) <= 20)
    np.testing.assert_array_equal(finite[1], np.abs(d - 10) <= 10)


def test_save_and_load_round_trip(models, tmp_path):
    demos = models.smooth_demos(n_demos=2, n_steps=150, n_dims=7)
    model = HSMM(4, n_iter=3, n_position=3).fit(demos)
    path = tmp_path / "model.npz"
    model.save(path)
    loaded = HSMM.load(path)
    for name in ("means_", "covariances_", "transmat_", "duration_stds_", "occupancy_",
                 "data_range_"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(model, name))
    assert loaded.log_likelihood(demos[0]) == model.log_likelihood(demos[0])
    assert loaded.n_position == 3 and loaded.max_duration_ == model.max_duration_
    # The range of the training data, per dimension (reproduction clips k* to it).
    samples = np.concatenate(demos)
    np.testing.assert_array_equal(loaded.data_range_, [samples.min(0), samples.max(0)])


def test_load_rejects_damaged_and_other_version_files(models, tmp_path):
    model = HSMM(3, n_iter=2).fit(models.smooth_demos(n_demos=2, n_steps=100, n_dims=4))
    good = tmp_path / "good.npz"
    model.save(good)

    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[:200])
    with pytest.raises(ValueError, match="truncated.npz"):
        HSMM.load(truncated)

    text = tmp_path / "text.npz"
    text.write_text("not a model\n")
    with pytest.raises(ValueError, match="text.npz"):
        HSMM.load(text)

    with np.load(good) as data:
        arrays = dict(data)
    np.savez(tmp_path / "future.npz", **{**arrays, "format_version": np.array(3)})
    with pytest.raises(ValueError, match="version 3"):
        HSMM.load(tmp_path / "future.npz")

    older = {key: value for key, value in arrays.items() if key != "data_range_"}
    np.savez(tmp_path / "older.npz", **{**older, "format_version": np.array(1)})
    with pytest.raises(ValueError, match="version 1, this code reads 2 .fit the model again"):
        HSMM.load(tmp_path / "older.npz")

    np.savez(tmp_path / "range.npz", **{**arrays, "data_range_": arrays["data_range_"][::-1]})
    with pytest.raises(ValueError, match="data_range_ minimum > maximum"):
        HSMM.load(tmp_path / "range.npz")

    # The EM history is optional: without it the model loads, with an empty history.
    np.savez(tmp_path / "no_history.npz", **{
        key: value for key, value in arrays.items() if key != "log_likelihood_history_"
    })  # fmt: skip
    bare = HSMM.load(tmp_path / "no_history.npz")
    assert bare.log_likelihood_history_ == [] and bare.n_iter_ == 0
    np.testing.assert_array_equal(bare.means_, model.means_)

    np.savez(tmp_path / "bad.npz", **{**arrays, "transmat_": arrays["transmat_"][:2]})
    with pytest.raises(ValueError, match="transmat_"):
        HSMM.load(tmp_path / "bad.npz")

    with pytest.raises(FileNotFoundError):
        HSMM.load(tmp_path / "missing.npz")


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(n_states=0), "n_states"),
        (dict(n_states=2.5), "n_states"),
        (dict(n_states=2, max_duration=0), "max_duration"),
        (dict(n_states=2, reg_covar=0.0), "reg_covar"),
        (dict(n_states=2, init="random"), "init"),
        (dict(n_states=2, n_iter=0), "n_iter"),
        (dict(n_states=2, max_duration=2.5), "max_duration"),
        (dict(n_states=2, min_duration_std=0.0), "min_duration_std"),
        (dict(n_states=2, tol=-1.0), "tol"),
        (dict(n_states=2, n_init=0), "n_init"),
        (dict(n_states=2, n_position=0), "n_position"),
        (dict(n_states=2, random_state=None), "random_state"),
        (dict(n_states=2, random_state=-1), "random_state"),
    ],
)
def test_bad_parameters_are_rejected(kwargs, message):
    model = HSMM(**kwargs)  # scikit-learn's convention: stored as given, checked by fit
    with pytest.raises(ValueError, match=message):
        model.fit(np.random.default_rng(0).standard_normal((20, 4)))


def test_bad_demos_are_rejected():
    rng = np.random.default_rng(0)
    good = rng.standard_normal((20, 3))
    with_nan = good.copy()
    with_nan[3, 1] = np.nan
    with pytest.raises(ValueError, match="demonstration 2 contains NaN"):
        HSMM(2).fit([good, with_nan])
    with pytest.raises(ValueError, match="demonstration 1 contains NaN or inf"):
        HSMM(2).fit([np.where(with_nan == with_nan, good, np.inf)])
    with pytest.raises(ValueError, match="demonstration 2 has D = 2"):
        HSMM(2).fit([good, good[:, :2]])
    with pytest.raises(ValueError, match=r"demonstration 2 has 3 samples \(steps\), fewer than the N = 4 states"):
        HSMM(4).fit([good, good[:3]])
    with pytest.raises(ValueError, match="shape"):
        HSMM(2).fit([good[:, 0]])
    with pytest.raises(ValueError, match="max_duration"):
        HSMM(1, max_duration=5).fit([good])  # one state cannot last 20 steps


def test_model_and_data_of_different_dimension_are_rejected(models):
    model = HSMM(2, n_iter=2).fit(models.smooth_demos(n_demos=2, n_steps=60, n_dims=4))
    wrong = np.zeros((10, 3))
    for method in (model.log_likelihood, model.predict_states, model.forward_variable):
        with pytest.raises(ValueError, match="model's is D = 4"):
            method(wrong)
    with pytest.raises(ValueError, match="not fitted"):
        HSMM(2).log_likelihood(wrong)
    with pytest.raises(ValueError, match="n_steps must be an integer >= 1"):
        model.forward_variable(0, observe=False)


def zig_zag(rng, counts=(50, 30, 40, 25)):
    """A hold-free zig-zag in 3-D: straight runs of ``counts`` samples between 5 corners."""
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.5], [0, 2, 0.5]], float)
    runs = [np.linspace(a, b, n, endpoint=False) for a, b, n in zip(corners, corners[1:], counts)]
    return np.concatenate(runs) + rng.normal(0.0, 1e-3, (sum(counts), 3))


def test_polyline_segments_cut_at_the_corners():
    rng = np.random.default_rng(0)
    path = zig_zag(rng)
    # A brute force over every pair of inner cuts finds the same least-squares cut.
    # Cut at the corners (a corner sample lies on both lines: either side will do).
    np.testing.assert_allclose(polyline_segments(path, 4), [0, 50, 80, 120, 145], atol=1)
    # In 3 pieces: the least-squares cut that a brute force over every pair of cuts finds.
    bounds = polyline_segments(path, 3)
    assert bounds[0] == 0 and bounds[-1] == len(path) and np.all(np.diff(bounds) > 0)

    def residual(piece):
        centred = piece - piece.mean(axis=0)
        return np.sum(np.linalg.svd(centred, compute_uv=False)[1:] ** 2)

    best = min(
        (residual(path[:i]) + residual(path[i:j]) + residual(path[j:]), (i, j))
        for i in range(1, len(path) - 1) for j in range(i + 1, len(path))
    )  # fmt: skip
    assert tuple(bounds[1:3]) == best[1]
    # A long path is cut on every k-th point: the cuts land within k samples of the corners.
    long = zig_zag(rng, counts=(500, 300, 400, 250))
    cuts = polyline_segments(long, 4, max_points=300)[1:-1]
    assert np.all(np.abs(cuts - [500, 800, 1200]) <= 5)
    with pytest.raises(ValueError, match="cannot make 5 pieces"):
        polyline_segments(path[:4], 5)


def test_polyline_init_gives_a_state_per_straight_run(models):
    rng = np.random.default_rng(1)
    demos = []
    for _ in range(2):
        x = zig_zag(rng)
        demos.append(np.column_stack([x, np.gradient(x, 0.01, axis=0)]))
    model = HSMM(4, init="polyline", n_iter=5, random_state=0).fit(demos)
    # Left to right, and each state is one run: its mean velocity points along that run.
    assert np.allclose(np.triu(model.transmat_, 2), 0) and np.allclose(np.tril(model.transmat_), 0)
    runs = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0.5], [0, 1, 0]], float)
    runs /= np.linalg.norm(runs, axis=1, keepdims=True)
    directions = model.means_[:, 3:6] / np.linalg.norm(model.means_[:, 3:6], axis=1)[:, None]
    assert np.all(np.sum(directions * runs, axis=1) > 0.95)
    history = np.asarray(model.log_likelihood_history_)
    assert np.all(np.diff(history) >= -1e-9 * np.abs(history[1:]))


def test_a_dataset_or_a_nan_model_given_as_a_model_is_named_so(tmp_path, models):
    import numpy as np

    from hemg_drake.learning.hsmm import HSMM

    dataset = tmp_path / "dataset.npz"
    np.savez(dataset, metadata=np.array("{}"), **{"demo0.time": np.zeros(3)})
    with pytest.raises(ValueError, match="not an HSMM model: .* like a dataset .*hemg-drake learn"):
        HSMM.load(dataset)
    model = models.set_parameters(
        means=np.zeros((2, 1)), covariances=np.ones((2, 1, 1)), startprob=[1.0, 0.0],
        transmat=[[0, 1], [0, 0]], duration_means=[5, 5], duration_stds=[1, 1], max_duration=20,
    )  # fmt: skip
    model.means_[1, 0] = np.nan
    path = tmp_path / "nan.npz"
    model.save(path)
    with pytest.raises(ValueError, match=r"means_ holds NaN or inf$"):
        HSMM.load(path)
