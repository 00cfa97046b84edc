"""HSMM-GMR reproduction (eqs. 12-18): the three weightings on a smooth 3-D path."""

import numpy as np
import pytest

from hemg_drake.learning.hsmm import HSMM
from hemg_drake.learning.reproduce import reproduce


@pytest.mark.parametrize("weighting", ["temporal", "spatial", "forward"])
def test_reproduction_follows_the_mean_demonstration(path_task, weighting):
    mean = path_task.mean
    result = reproduce(path_task.model, mean[0, :3], len(mean), dt=0.01, weighting=weighting)

    extent = np.ptp(mean[:, :3], axis=0).max()
    rmse = np.sqrt(np.mean(np.sum((result.x - mean[:, :3]) ** 2, axis=1)))
    assert rmse < 0.05 * extent
    # The stiffness is just another GMR output: it follows the demos' stiffness channel.
    k_demo = mean[:, 6]
    assert np.sqrt(np.mean((result.k[:, 0] - k_demo) ** 2)) < 0.1 * np.ptp(k_demo)
    assert np.corrcoef(result.k[:, 0], k_demo)[0, 1] > 0.95
    # eq. 18, and weights that are distributions.
    np.testing.assert_allclose(np.diff(result.x, axis=0), 0.01 * result.xdot[:-1], atol=1e-15)
    np.testing.assert_allclose(result.h.sum(axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(result.t, 0.01 * np.arange(len(mean)))


def test_temporal_weights_are_the_forward_variable_without_observation(path_task):
    result = reproduce(path_task.model, path_task.mean[0, :3], 300, weighting="temporal")
    np.testing.assert_allclose(
        result.h, path_task.model.forward_variable(300, observe=False), rtol=1e-12, atol=1e-15
    )


@pytest.mark.parametrize("n_dims, n_position", [(6, 3), (4, 2)])
def test_layouts_without_stiffness(models, n_dims, n_position):
    # D = 6: [x, xdot] in 3-D; D = 4: planar handwriting-style [x, y, xdot, ydot].
    columns = [0, 1, 3, 4] if n_dims == 4 else list(range(6))
    demos = [d[:, columns] for d in models.smooth_demos(n_steps=200)]
    mean = np.mean([models.resample(d, 220) for d in demos], axis=0)[:, :n_position]
    model = HSMM(6, n_iter=10).fit(demos)
    assert list(model.position_dims_) == list(range(n_position))
    result = reproduce(model, mean[0], len(mean), dt=0.01)
    assert result.k is None and result.x.shape == mean.shape
    rmse = np.sqrt(np.mean(np.sum((result.x - mean) ** 2, axis=1)))
    assert rmse < 0.05 * np.ptp(mean, axis=0).max()


def test_bad_input_is_rejected(path_task):
    model, start = path_task.model, path_task.mean[0, :3]
    with pytest.raises(ValueError, match="weighting"):
        reproduce(model, start, 10, weighting="both")
    with pytest.raises(ValueError, match="dt"):
        reproduce(model, start, 10, dt=0.0)
    with pytest.raises(ValueError, match=r"start must have shape \(3,\)"):
        reproduce(model, start[:2], 10)
    with pytest.raises(ValueError, match="start contains NaN"):
        reproduce(model, np.array([0.0, np.nan, 0.0]), 10)
    with pytest.raises(ValueError, match="n_steps"):
        reproduce(model, start, 0)
    with pytest.raises(ValueError, match="not fitted"):
        reproduce(HSMM(3), start, 10)


@pytest.fixture(scope="module")
def line_model():
    """Three noisy demonstrations of a 10 cm straight move along x at 0.1 m/s."""
    rng = np.random.default_rng(3)
    demos = []
    for _ in range(3):
        t = np.arange(0.0, 1.0, 0.01)
        x = np.column_stack([0.1 * t, np.zeros_like(t), np.zeros_like(t)])
        x += rng.normal(0.0, 1e-3, x.shape)
        v = np.column_stack([np.full_like(t, 0.1), np.zeros_like(t), np.zeros_like(t)])
        v += rng.normal(0.0, 1e-3, v.shape)
        k = 50.0 + 100.0 * t + rng.normal(0.0, 1.0, len(t))
        demos.append(np.column_stack([x, v, k]))
    return HSMM(4, init="time", reg_covar=0.1, n_iter=10, random_state=0).fit(demos)


def test_with_no_restoring_gain_the_rollout_is_eqs_15_to_18(line_model):
    # An independent rollout: temporal weights, GMR's conditional mean, Euler (eq. 18).
    from hemg_drake.learning.gmr import Gmr

    start, n = np.array([0.0, 0.01, 0.0]), 60
    result = reproduce(line_model, start, n, weighting="temporal", restoring_gain=0.0)
    # Each state conditions within its 3-sigma support (tests/learning/test_gmr.py checks
    # that clip against a bisection).
    gmr = Gmr(
        priors=line_model.occupancy_, means=line_model.means_,
        covariances=line_model.covariances_, input_dims=[0, 1, 2], output_dims=[3, 4, 5, 6],
        support_radius=3.0,
    ).fit()  # fmt: skip
    h = line_model.forward_variable(n, observe=False)
    x = start
    for t in range(n):
        np.testing.assert_allclose(result.x[t], x, atol=1e-12)
        x = x + 0.01 * gmr.predict(x, weights=h[t])[0][:3]


def test_a_start_offset_across_the_path_decays_with_time_constant_one_over_kappa(line_model):
    start = np.array([0.0, 0.01, 0.0])  # 1 cm across the demonstrated path
    kappa, n = 4.0, 80
    carried = reproduce(line_model, start, n, weighting="temporal")
    restored = reproduce(line_model, start, n, weighting="temporal", restoring_gain=kappa)
    t = restored.t
    # Without the attractor the offset is carried along; with it, it decays as exp(-kappa t).
    assert np.all(np.abs(carried.x[:, 1]) > 0.008)
    expected = 0.01 * (1.0 - kappa * 0.01) ** np.arange(n)  # the Euler step of exp(-kappa t)
    np.testing.assert_allclose(restored.x[:, 1], expected, atol=1e-3)
    assert abs(restored.x[-1, 1]) < 0.01 * np.exp(-kappa * t[-1]) + 1e-3
    # Along the path the motion (the timing) is the same.
    np.testing.assert_allclose(restored.x[:, 0], carried.x[:, 0], atol=2e-3)


def test_stiffness_is_clipped_to_the_training_range(line_model):
    # 0.5 m before the start of the path GMR's regression (eq. 16) extrapolates the rising
    # stiffness below anything demonstrated; the reproduction keeps it in the data's range.
    from hemg_drake.learning.gmr import Gmr

    far = np.array([-0.5, 0.0, 0.0])
    result = reproduce(line_model, far, 5, weighting="temporal")
    gmr = Gmr(
        priors=line_model.occupancy_, means=line_model.means_,
        covariances=line_model.covariances_, input_dims=[0, 1, 2], output_dims=[3, 4, 5, 6],
    ).fit()  # fmt: skip
    raw = gmr.predict(far, weights=result.h[0])[0][3]
    low, high = line_model.data_range_[:, 6]
    assert raw < low - 20.0  # eq. 16 unbounded
    # Conditioned within each state's support, and kept in the data's range.
    assert low <= result.k[0, 0] <= high and result.k[0, 0] > raw + 20.0
    assert np.all((result.k >= low) & (result.k <= high))


@pytest.mark.parametrize("gain", [-1.0, np.nan, 100.0])
def test_bad_restoring_gain_is_rejected(path_task, gain):
    with pytest.raises(ValueError, match="restoring_gain"):
        reproduce(path_task.model, path_task.mean[0, :3], 10, restoring_gain=gain)


def test_a_state_that_holds_still_attracts_in_every_direction():
    # Demonstrations hold still for 0.5 s, then move along x: a start 1 cm off along x (the
    # later motion's direction) is pulled back during the hold too.
    rng = np.random.default_rng(4)
    demos = []
    for _ in range(3):
        t = np.arange(0.0, 1.5, 0.01)
        s = np.clip(t - 0.5, 0.0, None)
        x = np.column_stack([0.1 * s, np.zeros_like(t), np.zeros_like(t)])
        v = np.column_stack([0.1 * (t > 0.5), np.zeros_like(t), np.zeros_like(t)])
        data = np.column_stack([x, v, np.full_like(t, 50.0)])
        demos.append(data + rng.normal(0.0, 1e-3, data.shape))
    model = HSMM(3, init="time", reg_covar=0.1, n_iter=10, random_state=0).fit(demos)
    start = np.array([0.01, 0.0, 0.0])
    carried = reproduce(model, start, 40, weighting="temporal")
    restored = reproduce(model, start, 40, weighting="temporal", restoring_gain=4.0)
    assert abs(carried.x[-1, 0]) > 0.008
    assert abs(restored.x[-1, 0]) < 0.01 * np.exp(-4.0 * 0.39) + 1e-3


# ---------------------------------------------------------------- tracker="lqr"
@pytest.fixture(scope="module")
def pull_task():
    """A cotter-pin-like pull: hold, a 10 cm minimum-jerk rise along z, hold; 3 demos whose
    timing and final height vary (the last by +-3 mm), and their time-normalised mean."""
    rng = np.random.default_rng(5)
    demos = []
    for c in range(3):
        t = np.arange(0.0, 2.0 + 0.1 * c, 0.01)
        s = np.clip((t - 0.4 - 0.05 * c) / (1.0 + 0.1 * c), 0.0, 1.0)
        height = 0.1 + 0.003 * (c - 1)
        z = height * (10 * s**3 - 15 * s**4 + 6 * s**5)
        x = np.column_stack([np.zeros_like(t), np.zeros_like(t), 0.12 + z])
        x += rng.normal(0.0, 5e-4, x.shape)
        v = np.gradient(x, 0.01, axis=0)
        k = 20.0 + 150.0 * np.sin(np.pi * s) + rng.normal(0.0, 1.0, len(t))
        demos.append(np.column_stack([x, v, k]))
    n = int(round(np.mean([len(d) for d in demos])))
    phase = np.linspace(0.0, 1.0, n)
    mean = np.mean(
        [np.column_stack([np.interp(phase, np.linspace(0, 1, len(d)), col) for col in d.T])
         for d in demos],
        axis=0,
    )  # fmt: skip
    model = HSMM(5, init="time", reg_covar=0.1, n_iter=20, random_state=0).fit(demos)
    return model, mean


def window_control(A, B, Q, Qm, R, s0):
    """First control of the H-step tracking problem, by least squares over all H controls."""
    horizon, (n, m) = len(Q) - 1, B.shape
    G = np.zeros(((horizon + 1) * n, horizon * m))
    g = np.zeros((horizon + 1) * n)
    for t in range(horizon + 1):
        g[t * n : (t + 1) * n] = np.linalg.matrix_power(A, t) @ s0
        for j in range(t):
            G[t * n : (t + 1) * n, j * m : (j + 1) * m] = np.linalg.matrix_power(A, t - 1 - j) @ B
    weights = np.zeros(((horizon + 1) * n,) * 2)
    linear = np.concatenate(Qm)
    for t in range(horizon + 1):
        weights[t * n : (t + 1) * n, t * n : (t + 1) * n] = Q[t]
    # d/du [ (Gu + g)^T W (Gu + g) - 2 (Gu + g)^T l + u^T R u ] = 0
    hessian = G.T @ weights @ G + np.kron(np.eye(horizon), R)
    return np.linalg.solve(hessian, G.T @ (linear - weights @ g))[:m]


def state_weights(h, state_cost):
    """w of the LQR's cost: h, or the one-hot of the most probable state."""
    return h if state_cost == "mixture" else np.eye(h.shape[1])[np.argmax(h, axis=1)]


@pytest.mark.parametrize("state_cost", ["active", "mixture"])
def test_lqr_tracker_is_the_receding_horizon_plan_on_the_timing(pull_task, state_cost):
    # Independent: weights from the model's forward variable, each state's precision over
    # [x, xdot], every step's plan by batch least squares, the double integrator by hand.
    # From 30 steps on, the 8-step horizons see a state change (where the costs differ).
    from hemg_drake.learning.gmr import Gmr

    model, mean = pull_task
    dt, horizon, r, n = 0.01, 8, 0.5, 60
    start = mean[0, :3] + [0.0, 0.005, 0.0]
    result = reproduce(
        model, start, n, dt=dt, weighting="temporal", tracker="lqr", horizon=horizon,
        control_cost=r, state_cost=state_cost,
    )  # fmt: skip
    h = model.forward_variable(n + horizon, observe=False)
    assert np.argmax(h[30]) != np.argmax(h[n + horizon - 1])
    w = state_weights(h, state_cost)
    precisions = np.linalg.inv(model.covariances_[:, :6, :6])
    Q = np.einsum("tn,nij->tij", w, precisions)
    Qm = np.einsum("tn,nij,nj->ti", w, precisions, model.means_[:, :6])
    A = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    B = np.vstack([0.5 * dt**2 * np.eye(3), dt * np.eye(3)])
    gmr = Gmr(
        priors=model.occupancy_, means=model.means_, covariances=model.covariances_,
        input_dims=[0, 1, 2], output_dims=[6], support_radius=3.0,
    ).fit()  # fmt: skip
    low, high = model.data_range_[:, 6]
    s = np.concatenate([start, np.zeros(3)])
    for t in range(n):
        np.testing.assert_allclose(result.x[t], s[:3], rtol=0, atol=1e-10)
        np.testing.assert_allclose(result.xdot[t], s[3:], rtol=0, atol=1e-9)
        np.testing.assert_allclose(result.h[t], h[t], atol=1e-12)
        k = np.clip(gmr.predict(s[:3], weights=h[t])[0], low, high)
        np.testing.assert_allclose(result.k[t], k, rtol=1e-10)
        u = window_control(A, B, Q[t : t + horizon + 1], Qm[t : t + horizon + 1], r * np.eye(3), s)
        s = A @ s + B @ u


@pytest.mark.parametrize("state_cost", ["active", "mixture"])
@pytest.mark.parametrize("weighting", ["temporal", "forward"])
def test_lqr_tracker_follows_the_mean_demonstration_without_overshoot(
    pull_task, weighting, state_cost
):
    model, mean = pull_task
    result = reproduce(
        model, mean[0, :3], len(mean), weighting=weighting, tracker="lqr", state_cost=state_cost
    )
    rmse = np.sqrt(np.mean(np.sum((result.x - mean[:, :3]) ** 2, axis=1)))
    assert rmse < 0.05 * 0.1  # 5 % of the 10 cm pull
    # The final height: demonstrated 0.217-0.223 m; no overshoot beyond the highest.
    assert result.x[:, 2].max() < 0.223 + 1e-3
    assert abs(result.x[-1, 2] - mean[-1, 2]) < 2e-3
    # The stiffness follows the demonstrated one (GMR's conditional k, clipped).
    assert np.corrcoef(result.k[:, 0], mean[:, 6])[0, 1] > 0.9
    np.testing.assert_allclose(result.h.sum(axis=1), 1.0, rtol=1e-12)
    np.testing.assert_array_equal(result.xdot[0], 0.0)  # from rest


def test_lqr_tracker_returns_to_the_path_from_an_offset(pull_task):
    # The states agree across the pull to about a millimetre: 1 cm aside is pulled back.
    model, mean = pull_task
    result = reproduce(model, mean[0, :3] + [0.01, 0.0, 0.0], 100, tracker="lqr",
                       weighting="temporal")  # fmt: skip
    assert abs(result.x[-1, 0]) < 1e-3


def test_the_gmr_tracker_is_the_default_path(path_task):
    model, start = path_task.model, path_task.mean[0, :3] + [0.0, 0.01, 0.0]
    for weighting in ("temporal", "spatial", "forward"):
        default = reproduce(model, start, 120, weighting=weighting, restoring_gain=2.0)
        named = reproduce(model, start, 120, weighting=weighting, restoring_gain=2.0,
                          tracker="gmr", horizon=3, control_cost=7.0)  # fmt: skip
        for field in ("t", "x", "xdot", "k", "h"):
            np.testing.assert_array_equal(getattr(named, field), getattr(default, field))


def test_bad_tracker_settings_are_rejected(path_task):
    model, start = path_task.model, path_task.mean[0, :3]
    with pytest.raises(ValueError, match=r"tracker must be one of \('gmr', 'lqr'\), got 'LQR'"):
        reproduce(model, start, 10, tracker="LQR")
    with pytest.raises(ValueError, match="weighting must be one of .* with tracker='lqr'"):
        reproduce(model, start, 10, tracker="lqr", weighting="spatial")
    with pytest.raises(ValueError, match="restoring_gain is for tracker='gmr' only"):
        reproduce(model, start, 10, tracker="lqr", restoring_gain=2.0)
    with pytest.raises(ValueError, match="horizon must be an integer >= 1"):
        reproduce(model, start, 10, tracker="lqr", horizon=0)
    with pytest.raises(ValueError, match="control_cost must be a finite number > 0"):
        reproduce(model, start, 10, tracker="lqr", control_cost=-1.0)
    with pytest.raises(ValueError, match=r"state_cost must be one of \('active', 'mixture'\)"):
        reproduce(model, start, 10, tracker="lqr", state_cost="argmax")
    with pytest.raises(ValueError, match=r"start must have shape \(3,\)"):
        reproduce(model, start[:2], 10, tracker="lqr")


@pytest.mark.parametrize("state_cost", ["active", "mixture"])
def test_lqr_temporal_table_grows_for_a_model_that_never_settles(path_task, state_cost):
    # k-means states with loops in A: the timing alone never settles, so the table of gains
    # is extended when a step needs it; a step there is the plan on that step's horizon.
    from hemg_drake.learning import lqr
    from hemg_drake.learning.reproduce import HsmmLqrPolicy

    model = path_task.model
    policy = HsmmLqrPolicy(model, weighting="temporal", horizon=20, state_cost=state_cost)
    t = len(policy._gain_table) + 300
    x, xdot = path_task.mean[0, :3], np.array([0.01, 0.0, 0.0])
    _, _, x_next, _, _ = policy.step(t, x, xdot, None)
    assert len(policy._gain_table) > t
    h = state_weights(model.forward_variable(t + 21, observe=False)[t:], state_cost)
    precisions = np.linalg.inv(model.covariances_[:, :6, :6])
    Q = np.einsum("tn,nij->tij", h, precisions)
    Qm = np.einsum("tn,nij,nj->ti", h, precisions, model.means_[:, :6])
    A, B = lqr.double_integrator(3, 0.01)
    u = lqr.first_control(A, B, Q, Qm, np.eye(3), np.concatenate([x, xdot]))
    np.testing.assert_allclose(x_next, x + 0.01 * xdot + 0.5e-4 * u, rtol=0, atol=1e-12)
