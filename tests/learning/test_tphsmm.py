"""Task-parameterised HSMM: equivariance, the one-frame case, a task known in one frame."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hemg_drake.learning.hsmm import HSMM
from hemg_drake.learning.reproduce import reproduce
from hemg_drake.learning.tphsmm import TaskParameterisedHSMM, load_model

DT = 0.01


def yaw(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def path_in_object(n_steps, c, rng):
    """A pull-and-carry path written in the object frame (m), its stiffness (N/m)."""
    s = np.linspace(0.0, 1.0, n_steps) ** (1.0 + 0.05 * c)
    p_T = np.stack([0.05 * np.sin(np.pi * s), 0.02 * s, 0.1 * s**2], axis=1)
    p_T += 3e-4 * rng.standard_normal(p_T.shape)
    k = 50.0 + 100.0 * np.sin(np.pi * s)
    return p_T, k


def placed_demos(placements, seed=0):
    """World observations [x, xdot, k] of the object-frame path at each placement, with the
    frames (robot base at the origin, object at (yaw, position))."""
    rng = np.random.default_rng(seed)
    demos, frames = [], []
    for c, (angle, position) in enumerate(placements):
        p_T, k = path_in_object(160 + 10 * c, c, rng)
        R = yaw(angle)
        x = p_T @ R.T + position
        demos.append(np.column_stack([x, np.gradient(x, DT, axis=0), k]))
        frames.append((np.stack([np.eye(3), R]), np.stack([np.zeros(3), position])))
    return demos, frames


PLACEMENTS = [
    (0.0, np.array([0.6, -0.8, 0.1])),
    (0.5, np.array([0.7, -0.7, 0.12])),
    (-0.4, np.array([0.55, -0.9, 0.08])),
    (0.25, np.array([0.65, -0.6, 0.1])),
]


@pytest.fixture(scope="module")
def fitted():
    demos, frames = placed_demos(PLACEMENTS)
    model = TaskParameterisedHSMM(5, init="time", n_iter=15, reg_covar=1e-2).fit(demos, frames)
    return demos, frames, model


def test_equivariance_under_a_rigid_motion(fitted):
    demos, frames, model = fitted
    R = Rotation.from_rotvec([0.3, -0.7, 1.1]).as_matrix()
    p = np.array([0.4, -1.3, 0.25])
    moved_demos = [np.column_stack([d[:, :3] @ R.T + p, d[:, 3:6] @ R.T, d[:, 6]]) for d in demos]
    moved_frames = [(R @ A, b @ R.T + p) for A, b in frames]
    moved = TaskParameterisedHSMM(5, init="time", n_iter=15, reg_covar=1e-2).fit(
        moved_demos, moved_frames
    )
    A_new = np.stack([np.eye(3), yaw(0.8)])
    b_new = np.array([[0.0, 0.0, 0.0], [0.5, -0.75, 0.15]])
    start = b_new[1]
    for tracker, weighting, gain in (("gmr", "forward", 2.0), ("lqr", "temporal", 0.0)):
        rep = reproduce(model.at(A_new, b_new), start, 150, dt=DT, weighting=weighting,
                        restoring_gain=gain, tracker=tracker)  # fmt: skip
        rep_moved = reproduce(
            moved.at(R @ A_new, b_new @ R.T + p), R @ start + p, 150, dt=DT,
            weighting=weighting, restoring_gain=gain, tracker=tracker,
        )  # fmt: skip
        np.testing.assert_allclose(rep_moved.x, rep.x @ R.T + p, atol=1e-9, rtol=0)
        np.testing.assert_allclose(rep_moved.xdot, rep.xdot @ R.T, atol=1e-9, rtol=0)
        np.testing.assert_allclose(rep_moved.k, rep.k, rtol=1e-9)  # N/m: relative
        assert np.ptp(rep.x[:, 2]) > 0.05  # it did move


def test_states_hold_one_gaussian_per_frame(fitted):
    """No covariance between frames: the emission is the product of the frames' Gaussians."""
    _, _, model = fitted
    covariances = model.stacked_.covariances_
    base, scene = model._indices(0), model._indices(1)
    assert len(base) == 6 and len(scene) == 7  # the stiffness in the scene frame only
    assert np.all(covariances[:, base][:, :, scene] == 0.0)
    assert np.all(covariances[:, scene][:, :, base] == 0.0)
    for j in (0, 1):  # each frame's Gaussian a proper one
        np.linalg.cholesky(model.frame_gaussians(j)[1])


def test_one_identity_frame_is_the_plain_hsmm_bit_for_bit():
    demos, _ = placed_demos(PLACEMENTS[:3])
    identity = (np.eye(3)[None], np.zeros((1, 3)))
    settings = dict(init="polyline", n_iter=10, reg_covar=0.05)
    plain = HSMM(4, **settings).fit(demos)
    tp = TaskParameterisedHSMM(4, **settings).fit(demos, [identity] * 3).at(*identity)
    for name in ("means_", "covariances_", "transmat_", "startprob_", "duration_means_",
                 "duration_stds_", "occupancy_", "data_range_"):  # fmt: skip
        assert np.array_equal(getattr(tp, name), getattr(plain, name)), name
    assert tp.log_likelihood_history_ == plain.log_likelihood_history_
    for tracker, weighting, gain in (("gmr", "forward", 2.0), ("lqr", "temporal", 0.0)):
        a = reproduce(plain, demos[0][0, :3], 120, weighting=weighting, restoring_gain=gain,
                      tracker=tracker)  # fmt: skip
        b = reproduce(tp, demos[0][0, :3], 120, weighting=weighting, restoring_gain=gain,
                      tracker=tracker)  # fmt: skip
        for field in ("x", "xdot", "k", "h"):
            assert np.array_equal(getattr(a, field), getattr(b, field)), (tracker, field)


def test_a_task_fixed_in_the_object_frame_is_reproduced_where_the_object_is(fitted):
    demos, _, model = fitted
    rng = np.random.default_rng(0)
    mean_T = np.mean([path_in_object(160, c, rng)[0] for c in range(4)], axis=0)
    means_T, _ = model.frame_gaussians(1)
    assert means_T.shape == (5, 7)  # [x, xdot, k] in the object frame
    world = HSMM(5, init="time", n_iter=15, reg_covar=1e-2).fit(demos)
    # Inside the demonstrated yaws and positions, and beyond them (turned and moved further).
    for angle, b_new, mean_tol, path_tol in (
        (0.1, np.array([0.62, -0.75, 0.1]), 0.002, 0.003),
        (-0.9, np.array([0.45, -0.65, 0.05]), 0.02, 0.008),
    ):
        R_new = yaw(angle)
        hsmm = model.at(np.stack([np.eye(3), R_new]), np.stack([np.zeros(3), b_new]))
        # The answer is the object frame's: its states' means, mapped to the new placement.
        error = np.linalg.norm(hsmm.means_[:, :3] - (means_T[:, :3] @ R_new.T + b_new), axis=1)
        assert np.max(error) < mean_tol
        expected = mean_T @ R_new.T + b_new
        rep = reproduce(hsmm, b_new, 200, dt=DT, weighting="temporal", tracker="lqr")
        off_path = np.min(np.linalg.norm(rep.x[:, None] - expected[None], axis=2), axis=1)
        assert np.max(off_path) < path_tol
        assert rep.x[-1, 2] - b_new[2] > 0.07  # most of the 0.1 m rise done
        # The world-frame HSMM goes where the demonstrations were, not where the object is.
        baseline = reproduce(world, b_new, 200, dt=DT, weighting="temporal", tracker="lqr")
        far = np.min(np.linalg.norm(baseline.x[:, None] - expected[None], axis=2), axis=1)
        assert np.max(far) > 3 * np.max(off_path)
    # Timing and the stiffness range carry over.
    assert np.array_equal(hsmm.duration_means_, model.stacked_.duration_means_)
    assert np.array_equal(hsmm.data_range_[:, 6], model.stacked_.data_range_[:, -1])


def test_save_load_round_trip_and_older_models(fitted, tmp_path):
    demos, _, model = fitted
    model.save(tmp_path / "tp.npz")
    loaded = load_model(tmp_path / "tp.npz")
    assert isinstance(loaded, TaskParameterisedHSMM) and loaded.n_frames_ == 2
    A, b = np.stack([np.eye(3), yaw(0.2)]), np.array([[0, 0, 0], [0.6, -0.7, 0.1]])
    for name in ("means_", "covariances_", "transmat_", "data_range_"):
        assert np.array_equal(getattr(loaded.at(A, b), name), getattr(model.at(A, b), name))
    plain = HSMM(3, init="time", n_iter=3).fit(demos)
    plain.save(tmp_path / "plain.npz")
    assert type(load_model(tmp_path / "plain.npz")) is HSMM  # format 2 still loads
    with pytest.raises(ValueError, match="TP-HSMM model format version 2"):
        TaskParameterisedHSMM.load(tmp_path / "plain.npz")
    with pytest.raises(FileNotFoundError):
        load_model(tmp_path / "missing.npz")
    # A file written when the parameters were given as **parameters with ``seed``.
    with np.load(tmp_path / "tp.npz") as data:
        arrays = dict(data)
    settings = json.loads(str(arrays["settings"]))
    settings["parameters"] = {"init": "time", "n_iter": 15, "seed": 4}
    np.savez(tmp_path / "old.npz", **{**arrays, "settings": np.array(json.dumps(settings))})
    old = TaskParameterisedHSMM.load(tmp_path / "old.npz")
    assert old.random_state == 4 and old.init == "time" and old.reg_covar == 1e-2
    assert np.array_equal(old.at(A, b).means_, model.at(A, b).means_)


def test_bad_frames_are_refused(fitted):
    demos, frames, model = fitted
    with pytest.raises(ValueError, match="for each of the 4 demos, got 2"):
        TaskParameterisedHSMM(3).fit(demos, frames[:2])
    with pytest.raises(ValueError, match="the model has 2 task frames, got 1"):
        model.at(np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match="singular"):
        model.at(np.zeros((2, 3, 3)), np.zeros((2, 3)))
    with pytest.raises(TypeError, match="unexpected keyword argument 'colour'"):
        TaskParameterisedHSMM(3, colour="red")
    with pytest.raises(ValueError, match="init must be one of"):
        TaskParameterisedHSMM(3, init="random").fit(demos, frames)  # checked by fit


def test_the_tp_hsmm_takes_the_hsmm_parameters_with_their_defaults():
    import inspect

    from sklearn.base import BaseEstimator, clone

    def defaults(cls):
        return {name: p.default for name, p in inspect.signature(cls).parameters.items()}

    assert defaults(TaskParameterisedHSMM) == defaults(HSMM)
    model = TaskParameterisedHSMM(4, init="time", random_state=2)
    assert isinstance(model, BaseEstimator)
    assert clone(model).get_params() == model.get_params()
    assert repr(model) == "TaskParameterisedHSMM(init='time', n_states=4, random_state=2)"
