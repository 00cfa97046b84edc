"""A dimension that does not vary (a constant gain, a coordinate held still) still fits."""

import numpy as np
import pytest

from hemg_drake.learning.hsmm import HSMM


@pytest.mark.parametrize("init", ["time", "kmeans"])
def test_a_constant_dimension_keeps_a_floor_in_its_own_units(init):
    # x = 0.6 exactly: numpy's std of it can be rounding noise (~1e-16), not 0, so a floor
    # relative to it would leave a singular covariance (Cholesky fails at reg_covar 1e-2).
    t = np.arange(0.0, 1.0 + 1e-9, 0.01)
    demos = []
    for c in range(2):
        line = np.column_stack([0.6 + 0 * t, -0.8 + 0 * t, 0.1 + 0.05 * t + 0.001 * c])
        demos.append(np.hstack([line, np.gradient(line, t, axis=0), 50.0 + 0 * t[:, None]]))
    # The case: spreads of 0 or of rounding noise (np.gradient of a constant, numpy's std).
    assert np.all(np.concatenate(demos)[:, [0, 1, 3, 4, 6]].std(axis=0) < 1e-14)
    model = HSMM(2, n_iter=3, init=init, reg_covar=1e-2, random_state=0).fit(demos)
    variances = model.covariances_.diagonal(axis1=1, axis2=2)
    # Constant dimensions (x, y, their rates, the gain) are floored at reg_covar itself.
    for column in (0, 1, 3, 4, 6):
        assert variances[:, column] == pytest.approx(1e-2, rel=1e-6)
    assert np.all(np.isfinite(model.log_likelihood_history_))
