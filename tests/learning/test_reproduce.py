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
