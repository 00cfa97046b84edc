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
    return HSMM(4, init="time", reg_covar=0.1, n_iter=10, seed=0).fit(demos)


def test_with_no_restoring_gain_the_rollout_is_eqs_15_to_18(line_model):
    # An independent rollout: temporal weights, GMR's conditional mean, Euler (eq. 18).
    from hemg_drake.learning.gmr import Gmr

    start, n = np.array([0.0, 0.01, 0.0]), 60
    result = reproduce(line_model, start, n, weighting="temporal", restoring_gain=0.0)
    gmr = Gmr(
        priors=line_model.occupancy_, means=line_model.means_,
        covariances=line_model.covariances_, input_dims=[0, 1, 2], output_dims=[3, 4, 5, 6],
    )  # fmt: skip
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
    )  # fmt: skip
    raw = gmr.predict(far, weights=result.h[0])[0][3]
    low, high = line_model.data_range_[:, 6]
    assert raw < low - 20.0
    assert result.k[0, 0] == pytest.approx(low)
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
    model = HSMM(3, init="time", reg_covar=0.1, n_iter=10, seed=0).fit(demos)
    start = np.array([0.01, 0.0, 0.0])
    carried = reproduce(model, start, 40, weighting="temporal")
    restored = reproduce(model, start, 40, weighting="temporal", restoring_gain=4.0)
    assert abs(carried.x[-1, 0]) > 0.008
    assert abs(restored.x[-1, 0]) < 0.01 * np.exp(-4.0 * 0.39) + 1e-3
