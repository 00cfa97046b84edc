"""Small hand-set HSMMs, a sampler and smooth 3-D demonstrations for the learning tests."""

from types import SimpleNamespace

import numpy as np
import pytest

from hemg_drake.learning.hsmm import HSMM


def set_parameters(*, means, covariances, startprob, transmat, duration_means,
                   duration_stds, max_duration, n_position=None):
    """An HSMM with the given parameters, as if fitted."""
    model = HSMM(len(means), max_duration=max_duration, n_position=n_position)
    model.means_ = np.asarray(means, dtype=float)
    model.covariances_ = np.asarray(covariances, dtype=float)
    model.startprob_ = np.asarray(startprob, dtype=float)
    model.transmat_ = np.asarray(transmat, dtype=float)
    model.duration_means_ = np.asarray(duration_means, dtype=float)
    model.duration_stds_ = np.asarray(duration_stds, dtype=float)
    model.occupancy_ = np.full(len(means), 1.0 / len(means))
    model.data_range_ = np.outer([-np.inf, np.inf], np.ones(model.means_.shape[1]))  # no data
    model.max_duration_ = max_duration
    model.log_likelihood_history_ = []
    return model


def random_model(rng, n_states, n_dims, max_duration):
    """Random full-covariance HSMM with a random zero-diagonal transition matrix."""
    factors = rng.standard_normal((n_states, n_dims, n_dims))
    transmat = rng.uniform(0.1, 1.0, (n_states, n_states))
    np.fill_diagonal(transmat, 0.0)
    return set_parameters(
        means=rng.standard_normal((n_states, n_dims)),
        covariances=factors @ factors.transpose(0, 2, 1) + 0.5 * np.eye(n_dims),
        startprob=rng.dirichlet(np.ones(n_states)),
        transmat=transmat / transmat.sum(axis=1, keepdims=True),
        duration_means=rng.uniform(1.0, max_duration, n_states),
        duration_stds=rng.uniform(0.5, 2.0, n_states),
        max_duration=max_duration,
    )


def sample(rng, *, means, covariances, startprob, transmat, duration_means,
           duration_stds, n_segments):
    """Observations and states of ``n_segments`` complete segments of an HSMM."""
    states, observations = [], []
    state = rng.choice(len(means), p=startprob)
    for _ in range(n_segments):
        duration = max(1, int(round(rng.normal(duration_means[state], duration_stds[state]))))
        observations.append(
            rng.multivariate_normal(means[state], covariances[state], size=duration)
        )
        states += [state] * duration
        state = rng.choice(len(means), p=transmat[state])
    return np.concatenate(observations), np.array(states)


def smooth_demos(*, n_demos=3, n_steps=500, dt=0.01, noise=5e-4, n_dims=7, seed=0):
    """Noisy demonstrations of one smooth 3-D path with a stiffness channel.

    Columns [x (3), xdot (3), k (1)] in m, m/s, N/m (the first ``n_dims``);
    each demo has its own noise and a slightly different speed.
    """
    rng = np.random.default_rng(seed)
    demos = []
    for c in range(n_demos):
        s = np.linspace(0.0, 1.0, n_steps + 20 * c) ** (1.0 + 0.05 * c)
        x = 0.1 * np.stack([np.sin(2 * np.pi * s), np.cos(np.pi * s), 0.5 * s], axis=1)
        x += noise * rng.standard_normal(x.shape)
        xdot = np.gradient(x, dt, axis=0)
        k = 100.0 + 300.0 * np.sin(np.pi * s)[:, None]  # stiff in the middle of the task
        demos.append(np.hstack([x, xdot, k])[:, :n_dims])
    return demos


@pytest.fixture
def models():
    """Helpers: set_parameters, random_model, sample, smooth_demos."""
    return SimpleNamespace(
        set_parameters=set_parameters,
        random_model=random_model,
        sample=sample,
        smooth_demos=smooth_demos,
        resample=resample,
    )


def resample(demo, n_steps):
    """``demo`` linearly resampled over its phase to ``n_steps`` rows."""
    phase = np.linspace(0.0, 1.0, len(demo))
    target = np.linspace(0.0, 1.0, n_steps)
    return np.stack([np.interp(target, phase, column) for column in demo.T], axis=1)


@pytest.fixture(scope="session")
def path_task():
    """A model fitted to three noisy 3-D path demos with stiffness, and their mean."""
    demos = smooth_demos()
    n_steps = int(round(np.mean([len(d) for d in demos])))
    mean = np.mean([resample(d, n_steps) for d in demos], axis=0)
    model = HSMM(8, n_iter=20, random_state=0).fit(demos)
    return SimpleNamespace(demos=demos, mean=mean, model=model)


def rotation_of_quaternion(wxyz):
    """Rotation matrices (n, 3, 3) of unit quaternions (n, 4) [w, x, y, z], written out."""
    w, x, y, z = np.moveaxis(np.asarray(wxyz, dtype=float), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)  # fmt: skip


def random_demonstration(seed, length, arm=True):
    """A Demonstration of seeded random but well-shaped data (sEMG at twice the rate); with
    ``arm``, random joint positions and tool rotations (q, R_WE), else None (an older
    dataset)."""
    from hemg_drake.learning.demos import Demonstration

    rng = np.random.default_rng(seed)
    fields = {}
    if arm:  # drawn from their own stream: the other fields are the same either way
        arm_rng = np.random.default_rng([seed, 1])
        quats = arm_rng.normal(size=(length, 4))
        quats /= np.linalg.norm(quats, axis=1, keepdims=True)
        fields = {"q": arm_rng.uniform(-3, 3, (length, 7)), "R_WE": rotation_of_quaternion(quats)}
    return Demonstration(
        seed=seed,
        time=np.arange(length) * 0.01,
        p_WE=rng.normal(size=(length, 3)),
        v_WE=rng.normal(size=(length, 3)),
        p_MS=rng.normal(size=(length, 3)),
        envelope=rng.uniform(0, 50, length),
        activation=rng.uniform(0, 1, length),
        gain=rng.uniform(10, 200, length),
        f_WE=rng.normal(size=(length, 3)),
        p_WE_desired=rng.normal(size=(length, 3)),
        emg_time=np.arange(2 * length) * 0.005,
        emg=rng.integers(-128, 128, size=(2 * length, 8)).astype(float),
        muscle_activation=rng.uniform(0, 1, 2 * length),
        **fields,
    )


@pytest.fixture
def quaternion_rotation():
    """rotation_of_quaternion: closed-form matrices of [w, x, y, z] quaternions."""
    return rotation_of_quaternion


@pytest.fixture
def make_demo():
    """random_demonstration(seed, length), for dataset and export tests."""
    return random_demonstration
