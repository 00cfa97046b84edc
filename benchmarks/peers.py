"""The HSMM against its peers on the same data: hmmlearn, gaussian-hsmm, liblrhsmm-rs.

Each method is fitted to the training demonstrations and scored on held-out ones, in
nats per sample of the original units (a method given standardised data has its score
moved back by sum_d log scale_d). Regimes: "left-to-right" is a time-split initialisation
whose zeros in A stay zero (the HSMM's ``init="time"``; liblrhsmm-rs, whose segmentation
fixes the state order, is only this); "ergodic" is a k-means (or HMM) initialisation, any
state after any other (the HSMM's default, hmmlearn, gaussian-hsmm).

Used by ``bench_learning.py --peers``; a peer that is not installed is left out.
"""

import time

import numpy as np

from hemg_drake.learning.hsmm import HSMM

TOL = 1e-3  # nats per sample, the HSMM's default stopping rule, for liblrhsmm-rs too
MAX_ITER = 100


def _cpu(function):
    begin = time.process_time()
    result = function()
    return time.process_time() - begin, result


class Standardised:
    """Training data's mean and spread; the log-density change of standardising."""

    def __init__(self, train):
        samples = np.concatenate(train)
        self.mean, self.scale = samples.mean(axis=0), samples.std(axis=0)

    def __call__(self, demos):
        return [(d - self.mean) / self.scale for d in demos]

    def per_sample(self, log_likelihood, n_samples):
        """A standardised-data log-likelihood in nats per sample of the original units."""
        return log_likelihood / n_samples - np.sum(np.log(self.scale))


def fit_hsmm(train, test, n_states, init):
    seconds, model = _cpu(lambda: HSMM(n_states, init=init).fit(train))
    n_test = sum(map(len, test))
    return {"seconds": seconds, "iterations": model.n_iter_, "model": model,
            "held_out": model.score(test) / n_test}  # fmt: skip


def hsmm_time_to(train, test, n_states, init, target):
    """CPU s of the HSMM fit with the fewest EM iterations whose held-out score reaches
    ``target`` (nats per sample), and that count; (nan, None) if the converged fit does not."""
    n_test = sum(map(len, test))
    for n_iter in range(1, MAX_ITER + 1):
        seconds, model = _cpu(lambda: HSMM(n_states, init=init, n_iter=n_iter).fit(train))
        if model.score(test) / n_test >= target:
            return seconds, n_iter
        if model.converged_:
            return np.nan, None
    return np.nan, None


def fit_hmmlearn(train, test, n_states):
    from hmmlearn.hmm import GaussianHMM

    standard = Standardised(train)
    hmm = GaussianHMM(n_states, covariance_type="full", tol=1e-2, n_iter=MAX_ITER,
                      random_state=0)  # fmt: skip
    x, lengths = np.concatenate(standard(train)), [len(d) for d in train]
    seconds, _ = _cpu(lambda: hmm.fit(x, lengths))
    test_x = np.concatenate(standard(test))
    return {"seconds": seconds, "iterations": hmm.monitor_.iter,
            "held_out": standard.per_sample(hmm.score(test_x, [len(d) for d in test]),
                                            len(test_x))}  # fmt: skip


def fit_gaussian_hsmm(train, test, n_states, max_duration):
    """gaussian-hsmm's GaussianHSMM (full covariances; its HMM initialisation; shifted
    Poisson durations), on standardised data; None if not installed."""
    try:
        from gaussian_hsmm import GaussianHSMM
    except ImportError:
        return None
    standard = Standardised(train)
    x, lengths = np.concatenate(standard(train)), [len(d) for d in train]
    model = GaussianHSMM(n_components=n_states, covariance_type="full",
                         max_duration=max_duration, n_iter=MAX_ITER,
                         tol=TOL * len(x), random_state=0)  # fmt: skip
    seconds, _ = _cpu(lambda: model.fit(x, lengths))
    test_x = np.concatenate(standard(test))
    score = model.score(test_x, [len(d) for d in test])
    return {"seconds": seconds, "iterations": model.monitor_.iter, "model": model,
            "standard": standard,
            "held_out": standard.per_sample(score, len(test_x))}  # fmt: skip


def _lrh_data(lib, demos, n_states):
    observations, segmentations = [], []
    for demo in demos:
        n_steps, n_dims = demo.shape
        observation = lib.ObservationF64(n_steps, [n_dims])
        observation.set_stream(0, lib.ObservationStreamF64(n_dims, demo.ravel().tolist()))
        segmentation = lib.SegmentationF64(1, n_states)
        ends = [(i + 1) * n_steps // n_states for i in range(n_states)]  # time split
        segmentation.set_boundaries(ends)
        segmentation.set_duration_states(list(range(n_states)))
        segmentation.set_output_states(0, list(range(n_states)))
        observations.append(observation)
        segmentations.append(segmentation)
    return observations, segmentations


def _lrh_score(lib, model, observations, segmentations):
    options = lib.HsmmOptionsF64()
    statistics = lib.ModelStatisticsF64.from_model(model)
    return sum(statistics.estimate_hsmm(model, o, s, options)
               for o, s in zip(observations, segmentations))  # fmt: skip


def fit_liblrhsmm(train, test, n_states, reg_covar=1e-2):
    """liblrhsmm-rs: left-to-right HSMM (diagonal Gaussians, Gaussian durations), the
    time-split initialisation, EM until a gain under TOL nats per sample, on standardised
    data with variances floored at ``reg_covar`` (the HSMM's default); None if not
    installed."""
    try:
        import liblrhsmm_rs as lib
    except ImportError:
        return None
    standard = Standardised(train)
    train_s, test_s = standard(train), standard(test)
    n_dims = train[0].shape[1]
    n_samples = sum(map(len, train))

    def fit():
        labels = [np.minimum(np.arange(len(d)) * n_states // len(d), n_states - 1)
                  for d in train_s]  # fmt: skip
        samples, flat = np.concatenate(train_s), np.concatenate(labels)
        stream = lib.StreamF64(n_states, 1, n_dims)
        builder = lib.ModelBuilderF64(1, n_states)
        for i in range(n_states):
            members = samples[flat == i]
            gaussian = lib.GaussianF64(1, n_dims)
            gaussian.replace(n_dims, [1.0], members.mean(axis=0).tolist(),
                             (members.var(axis=0) + reg_covar).tolist(),
                             [reg_covar] * n_dims)  # fmt: skip
            stream.set_emission(i, gaussian)
            runs = np.array([np.sum(label == i) for label in labels], dtype=float)
            duration = lib.DurationF64()
            duration.set_values([runs.mean(), max(runs.var(), 1.0), 1.0])
            builder.set_duration(i, duration)
        builder.set_stream(0, stream)
        model = builder.build()
        observations, segmentations = _lrh_data(lib, train_s, n_states)
        options, update = lib.HsmmOptionsF64(), lib.UpdateOptionsF64()
        update.emission_variance_floor = reg_covar
        history = []
        for _ in range(MAX_ITER):
            statistics = lib.ModelStatisticsF64.from_model(model)
            statistics.clear()
            history.append(sum(statistics.estimate_hsmm(model, o, s, options)
                               for o, s in zip(observations, segmentations)))  # fmt: skip
            model.update(statistics, update)
            if len(history) > 1 and history[-1] - history[-2] < TOL * n_samples:
                break
        return model, len(history)

    seconds, (model, iterations) = _cpu(fit)
    test_observations, test_segmentations = _lrh_data(lib, test_s, n_states)
    score = _lrh_score(lib, model, test_observations, test_segmentations)
    durations = np.array([model.duration(i).values()[:2] for i in range(n_states)])
    return {"seconds": seconds, "iterations": iterations, "durations": durations,
            "held_out": standard.per_sample(score, sum(map(len, test)))}  # fmt: skip


def versions():
    """Installed versions of the peers (None where not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    found = {}
    for name in ("hmmlearn", "gaussian-hsmm", "liblrhsmm-rs"):
        try:
            found[name] = version(name)
        except PackageNotFoundError:
            found[name] = None
    return found


# Synthetic left-to-right data with known durations (steps): 5 states in [x, y, xdot, ydot].
TRUE_MEANS = np.array([30.0, 50.0, 20.0, 40.0, 60.0])
TRUE_STDS = np.array([3.0, 5.0, 2.0, 4.0, 6.0])


def synthetic(n_demos, seed, noise=0.35):
    """Demonstrations of a known left-to-right HSMM and each one's true segment starts.

    State i emits N(m_i, noise^2 I), m_i on a zigzag (neighbours 1 apart in x, 1 in y);
    its durations are N(TRUE_MEANS[i], TRUE_STDS[i]^2), rounded, at least 1 step.
    """
    rng = np.random.default_rng(seed)
    n_states = len(TRUE_MEANS)
    centres = np.array([[i, (-1.0) ** i, 0.3 * i, 0.5 * (-1.0) ** i] for i in range(n_states)])
    demos, starts = [], []
    for _ in range(n_demos):
        durations = np.maximum(1, np.round(rng.normal(TRUE_MEANS, TRUE_STDS))).astype(int)
        labels = np.repeat(np.arange(n_states), durations)
        demos.append(centres[labels] + noise * rng.standard_normal((len(labels), 4)))
        starts.append(np.cumsum(durations)[:-1])
    return demos, starts, centres


def boundary_f1(true_starts, states, tolerance=3):
    """F1 of the decoded segment starts (state changes) against the true ones, a decoded
    start counting as found if within ``tolerance`` steps of an unmatched true one."""
    found = np.flatnonzero(np.diff(states)) + 1
    unmatched = list(true_starts)
    hits = 0
    for b in found:
        if unmatched:
            k = int(np.argmin(np.abs(np.array(unmatched) - b)))
            if abs(unmatched[k] - b) <= tolerance:
                hits += 1
                unmatched.pop(k)
    precision = hits / len(found) if len(found) else 0.0
    recall = hits / len(true_starts)
    return 0.0 if hits == 0 else 2 * precision * recall / (precision + recall)


def state_order(fitted_means, centres):
    """Which fitted state stands for each true state (Hungarian on the means' distances)."""
    from scipy.optimize import linear_sum_assignment

    cost = np.linalg.norm(fitted_means[:, None, :] - centres[None, :, :], axis=2)
    rows, columns = linear_sum_assignment(cost)
    order = np.empty(len(centres), dtype=int)
    order[columns] = rows
    return order


def duration_errors(means, stds, order):
    """Mean relative error of the duration means and spreads against the truth (%)."""
    mean_error = np.mean(np.abs(means[order] - TRUE_MEANS) / TRUE_MEANS)
    std_error = np.mean(np.abs(stds[order] - TRUE_STDS) / TRUE_STDS)
    return 100 * mean_error, 100 * std_error
