"""The learnt stiffness shapes (learning/stiffness.py) against closed forms and scipy."""

import numpy as np
import pytest
import scipy.linalg

from hemg_drake.learning.gmr import Gmr
from hemg_drake.learning.hsmm import HSMM
from hemg_drake.learning.stiffness import (
    SpdStiffness,
    log_euclidean_mean,
    state_log_shapes,
)


def rotation(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def random_spd(rng, n, spread=1.0):
    A = rng.standard_normal((n, n))
    values = np.exp(spread * rng.standard_normal(n))
    Q, _ = np.linalg.qr(A)
    return Q @ np.diag(values) @ Q.T


def test_a_shape_is_the_unit_determinant_precision_by_hand():
    # 2-D, spreads 1 cm and 2 cm along rotated axes: the precision diag(1/1, 1/4) (cm^-2)
    # at unit determinant is diag(2, 1/2), ratio 4 (inside rho = 10), in the same axes.
    R = rotation(0.3)
    covariance = R @ np.diag([1e-4, 4e-4]) @ R.T
    shape = scipy.linalg.expm(state_log_shapes(covariance[None], 10.0)[0])
    np.testing.assert_allclose(shape, R @ np.diag([2.0, 0.5]) @ R.T, atol=1e-12)


def test_the_eigenvalue_ratio_is_capped_by_hand():
    # 3-D, 10x the spread along z (variance 100x): precision ratio 100, capped at rho = 10.
    # Hand: log-eigenvalues centred (a, a, -2a), a = ln(100)/3, clipped to +-ln(10)/2 and
    # re-centred: eigenvalues 10^(1/3), 10^(1/3), 10^(-2/3).
    covariance = np.diag([1.0, 1.0, 100.0]) * 1e-6
    shape = scipy.linalg.expm(state_log_shapes(covariance[None], 10.0)[0])
    np.testing.assert_allclose(
        shape, np.diag([10 ** (1 / 3), 10 ** (1 / 3), 10 ** (-2 / 3)]), rtol=1e-12
    )


@pytest.mark.parametrize("n", [2, 3])
def test_every_interpolated_shape_is_spd_unit_determinant_and_bounded(n):
    rng = np.random.default_rng(n)
    covariances = np.array([random_spd(rng, n, spread=3.0) for _ in range(6)])
    logs = state_log_shapes(covariances, 10.0)
    for _ in range(300):
        h = rng.dirichlet(0.3 * np.ones(6))
        values = np.linalg.eigvalsh(log_euclidean_mean(h, logs))
        assert values.min() > 0
        assert np.prod(values) == pytest.approx(1.0, rel=1e-9)
        assert values.max() / values.min() <= 10.0 * (1 + 1e-9)


def test_two_matrix_mean_is_scipys_expm_of_the_weighted_logm():
    rng = np.random.default_rng(3)
    A, B = random_spd(rng, 3, 1.0), random_spd(rng, 3, 1.0)
    logs = np.array([scipy.linalg.logm(A).real, scipy.linalg.logm(B).real])
    for w in (0.0, 0.25, 0.5, 0.9):
        reference = scipy.linalg.expm(w * logs[0] + (1 - w) * logs[1])
        np.testing.assert_allclose(log_euclidean_mean([w, 1 - w], logs), reference, rtol=1e-9)


def test_commuting_matrices_meet_at_the_geodesic_midpoint():
    # For commuting A, B every SPD metric's geodesic is diag(a^(1-t) b^t); the midpoint is
    # also the affine-invariant one, A^1/2 (A^-1/2 B A^-1/2)^1/2 A^1/2.
    R = np.linalg.qr(np.random.default_rng(4).standard_normal((3, 3)))[0]
    a, b = np.array([4.0, 1.0, 0.25]), np.array([0.5, 2.0, 1.0])
    A, B = R @ np.diag(a) @ R.T, R @ np.diag(b) @ R.T
    logs = np.array([R @ np.diag(np.log(a)) @ R.T, R @ np.diag(np.log(b)) @ R.T])
    mid = log_euclidean_mean([0.5, 0.5], logs)
    np.testing.assert_allclose(mid, R @ np.diag(np.sqrt(a * b)) @ R.T, rtol=1e-12)
    root = scipy.linalg.sqrtm(A).real
    inverse_root = np.linalg.inv(root)
    affine = root @ scipy.linalg.sqrtm(inverse_root @ B @ inverse_root).real @ root
    np.testing.assert_allclose(mid, affine, rtol=1e-9)


def lasa_like_demos(n_dims, seed=0, n_demos=4, n_steps=300, dt=0.01):
    """LASA-like handwriting shapes (a C in 2-D, an S on a slope in 3-D) with a demonstrated
    stiffness stiff across the path (1000 N/m) and soft along it (50 N/m): columns
    [x (P), xdot (P), the stiffness' upper triangle] in m, m/s, N/m."""
    rng = np.random.default_rng(seed)
    demos = []
    for c in range(n_demos):
        s = np.linspace(0.0, 1.0, n_steps)
        if n_dims == 2:
            angle = np.pi * (0.5 + s)
            x = 0.1 * np.stack([np.cos(angle), np.sin(angle)], axis=1)
        else:
            x = 0.08 * np.stack(
                [np.sin(2 * np.pi * s), 2 * s - 1, 0.5 * s + 0.2 * np.sin(np.pi * s)], axis=1
            )
        x = x + 0.002 * c * rng.standard_normal(n_dims) + 3e-4 * rng.standard_normal(x.shape)
        xdot = np.gradient(x, dt, axis=0)
        along = xdot / np.linalg.norm(xdot, axis=1, keepdims=True)
        K = 1000.0 * np.eye(n_dims) - 950.0 * np.einsum("ti,tj->tij", along, along)
        upper = K[:, *np.triu_indices(n_dims)]
        demos.append(np.hstack([x, xdot, upper]))
    return demos


def unpack(upper, n_dims):
    K = np.zeros(upper.shape[:-1] + (n_dims, n_dims))
    rows, cols = np.triu_indices(n_dims)
    K[..., rows, cols] = upper
    K[..., cols, rows] = upper
    return K


@pytest.mark.parametrize("n_dims", [2, 3])
def test_elementwise_gmr_of_matrices_fails_where_the_spd_shape_holds(n_dims):
    demos = lasa_like_demos(n_dims)
    model = HSMM(6, n_position=n_dims, init="time", n_iter=20, random_state=0).fit(demos)
    n_upper = n_dims * (n_dims + 1) // 2
    elementwise = Gmr(
        priors=model.occupancy_, means=model.means_, covariances=model.covariances_,
        input_dims=model.position_dims_, output_dims=np.arange(2 * n_dims, 2 * n_dims + n_upper),
    ).fit()  # fmt: skip
    spd = SpdStiffness(model, max_ratio=10.0)
    # Queries on and beside the demonstrated path (up to 3 cm: a perturbed reproduction).
    path = np.mean(demos, axis=0)[:, :n_dims]
    rng = np.random.default_rng(1)
    queries = path[::5, None, :] + 0.03 * rng.uniform(-1, 1, (1, 8, n_dims))
    queries = np.concatenate([path[::5], queries.reshape(-1, n_dims)])
    weights = elementwise.responsibilities(queries)
    K_elementwise = unpack(elementwise.predict(queries)[0], n_dims)
    smallest = np.linalg.eigvalsh(K_elementwise).min(axis=1)
    assert np.mean(smallest <= 0) > 0.01, "element-wise GMR gave SPD matrices everywhere"
    shapes = np.array([spd.shape(h) for h in weights])
    values = np.linalg.eigvalsh(shapes)
    assert values.min() > 0
    np.testing.assert_allclose(np.prod(values, axis=1), 1.0, rtol=1e-9)
    assert (values.max(axis=1) / values.min(axis=1)).max() <= 10.0 * (1 + 1e-9)
    # And the shape is the demonstrations': on the path, softest along the motion.
    on_path = shapes[: len(path[::5])]
    direction = np.gradient(path, axis=0)[::5]
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    along = np.einsum("ti,tij,tj->t", direction, on_path, direction)
    softest = values[: len(on_path)].min(axis=1)
    largest = values[: len(on_path)].max(axis=1)
    assert np.median(along / largest) < 0.5
    assert np.median(along) < 2 * np.median(softest) + 0.5 * np.median(largest)


def test_bad_ratio_is_rejected():
    with pytest.raises(ValueError, match="max_ratio"):
        state_log_shapes(np.eye(3)[None], 0.5)
