"""Task-parameterised HSMM (Calinon 2016): states with a Gaussian in each task frame.

Each demonstration c comes with F task frames (A_j, b_j), j = 1 .. F: the frame's
rotation (P x P) and origin (P) in the world, e.g. the robot's base and the task object
(the pin's fixture, the sheet). The world observations xi = [x, xdot, k] are seen from
frame j as

    xi^(j) = [A_j^-1 (x - b_j), A_j^-1 xdot]     (+ k in the stiffness frame only)

and every state i holds a Gaussian N(mu_i^(j), Sigma_i^(j)) in each frame, with one
timing (pi, A, durations) shared by the frames. EM maximises prod_j N(xi^(j) | mu_i^(j),
Sigma_i^(j)) as the emission of state i (Calinon 2016, "A tutorial on task-parameterized
movement learning and retrieval", eqs. 4-7, with the HSMM's explicit durations). That
product is a Gaussian over the stacked observations [x^(1..F), xdot^(1..F), k] with a
block-diagonal covariance (one block per frame), so the HSMM's own EM and kernels
(:class:`~hemg_drake.learning.hsmm.HSMM`) run unchanged on the stacked data: the only
change is the M-step's covariance floor, which keeps the blocks and drops what lies
between frames (the exact constrained maximiser: the eigenvalue floor of a block-diagonal
matrix is block-diagonal). The stiffness sits in one frame (the last, the task object's)
so that its precision is counted once.

At a new placement, the new frames (A_j, b_j) map each state's frame Gaussians to the
world, N(T_j mu_i^(j) + o_j, T_j Sigma_i^(j) T_j^T) with T_j = blockdiag(A_j, A_j[, 1])
and o_j = [b_j, 0[, 0]], and their product is the state's world Gaussian (eq. 8)::

    Sigma_i = (sum_j Sigma_ij^-1)^-1,   mu_i = Sigma_i sum_j Sigma_ij^-1 mu_ij

(the frames without k leave it free: their precision is zero there). :meth:`at` returns
it as a plain fitted :class:`HSMM` (means_, covariances_ and the shared timing, occupancy
and stiffness range), which every reproduction path uses unchanged::

    model = TaskParameterisedHSMM(4, init="time").fit(demos, frames)
    hsmm = model.at(A_new, b_new)       # an HSMM for the placement (A_new, b_new)
    reproduce(hsmm, start, n_steps)

With one identity frame the stacked data are the world data and :meth:`at` gives the
plain HSMM fitted to them, bit for bit.

Model files (:meth:`save`) are format version 3 (HSMM files are version 2);
:func:`load_model` reads either.
"""

import json
from pathlib import Path

import numpy as np
from sklearn.base import BaseEstimator

from hemg_drake.fileio import load_npz
from hemg_drake.learning.hsmm import HSMM, check_demos
from hemg_drake.learning.hsmm_io import FITTED, load_fitted, save_fitted, settings_of
from hemg_drake.learning.hsmm_io import learnt_at_array, read_learnt_at
from hemg_drake.learning.hsmm_params import check_parameters
from hemg_drake.learning.sequences import check_fitted

FORMAT_VERSION = 3
KIND = "task-parameterised HSMM"


def check_frames(A, b, *, n_position=3, name="frames"):
    """Task frames as float arrays A (F, P, P), b (F, P); ValueError naming ``name``.

    Each A_j must be invertible (a rotation in practice) and every entry finite.
    """
    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    p = n_position
    if A.ndim == 2:
        A, b = A[None], b[None]
    if A.ndim != 3 or A.shape[1:] != (p, p) or b.shape != (len(A), p) or len(A) < 1:
        raise ValueError(
            f"{name} must be A of shape (F, {p}, {p}) and b of shape (F, {p}), F >= 1; got "
            f"{A.shape} and {b.shape}"
        )
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(b))):
        raise ValueError(f"{name} contain NaN or inf")
    if np.any(np.abs(np.linalg.det(A)) < 1e-12):
        raise ValueError(f"{name}: a frame's A is singular (give a rotation matrix)")
    return A, b


class _StackedHSMM(HSMM):
    """An HSMM over stacked per-frame observations whose covariances stay block-diagonal."""

    def floor_covariances(self, covariances, scale):
        mask = self._block_mask
        if mask.all():  # one frame: the plain HSMM's floor, on the same array
            return super().floor_covariances(covariances, scale)
        floored = super().floor_covariances(np.where(mask, covariances, 0.0), scale)
        return np.where(mask, floored, 0.0)


class TaskParameterisedHSMM(BaseEstimator):
    """HSMM whose states hold a Gaussian in each of F task frames (Calinon 2016).

    A scikit-learn estimator (``get_params``, ``set_params``, ``clone``) whose parameters
    are the :class:`~hemg_drake.learning.hsmm.HSMM`'s, with the same defaults and meaning:
    ``reg_covar`` is relative to each frame's per-dimension variance; ``init="kmeans"`` and
    ``"polyline"`` use the positions in all frames; ``n_position`` is P of the world
    observations. The constructor only stores them; :meth:`fit` checks them.

    Parameters
    ----------
    n_states : int
    max_duration, reg_covar, min_duration_std, n_iter, tol, init, n_init, n_position, random_state
        As for :class:`~hemg_drake.learning.hsmm.HSMM`.

    Attributes
    ----------
    n_frames_ : int
    stacked_ : HSMM
        The fitted model over [x^(1..F) (F P), xdot^(1..F) (F P), k (K)], block-diagonal.
    n_position_, n_stiffness_ : int
        P and K of the world observations [x (P), xdot (P), k (K)].
    """

    def __init__(
        self,
        n_states,
        *,
        max_duration=None,
        reg_covar=1e-2,
        min_duration_std=None,
        n_iter=100,
        tol=1e-3,
        init="kmeans",
        n_init=5,
        n_position=None,
        random_state=0,
    ):
        self.n_states = n_states
        self.max_duration = max_duration
        self.reg_covar = reg_covar
        self.min_duration_std = min_duration_std
        self.n_iter = n_iter
        self.tol = tol
        self.init = init
        self.n_init = n_init
        self.n_position = n_position
        self.random_state = random_state

    def __sklearn_is_fitted__(self):
        return hasattr(self, "stacked_")

    def _hsmm_parameters(self):
        """The HSMM parameters but n_states, as given."""
        return {k: v for k, v in self.get_params().items() if k != "n_states"}

    # -------------------------------------------------------------- layout
    def _indices(self, j):
        """Stacked indices of frame j's block: x^(j), xdot^(j) (and k for the last frame)."""
        f, p = self.n_frames_, self.n_position_
        index = [*range(p * j, p * j + p), *range(f * p + p * j, f * p + p * j + p)]
        if j == f - 1:
            index += range(2 * f * p, 2 * f * p + self.n_stiffness_)
        return np.array(index)

    def _block_mask(self):
        size = 2 * self.n_frames_ * self.n_position_ + self.n_stiffness_
        mask = np.zeros((size, size), dtype=bool)
        for j in range(self.n_frames_):
            index = self._indices(j)
            mask[np.ix_(index, index)] = True
        return mask

    def stack(self, demo, A, b):
        """One demonstration's world observations (T, D) seen from its frames: (T, D_s)."""
        p = self.n_position_
        A, b = check_frames(A, b, n_position=p)
        x, xdot, k = demo[:, :p], demo[:, p : 2 * p], demo[:, 2 * p :]
        # x^(j) = A_j^-1 (x - b_j): solve, exact for an identity frame.
        xs = [np.linalg.solve(A_j, (x - b_j).T).T for A_j, b_j in zip(A, b, strict=True)]
        xdots = [np.linalg.solve(A_j, xdot.T).T for A_j in A]
        return np.ascontiguousarray(np.hstack([*xs, *xdots, k]))  # layout changes EM sums

    def frame_gaussians(self, j):
        """State i's Gaussian in frame j: means (N, D_j), covariances (N, D_j, D_j)."""
        self._check_fitted()
        index = self._indices(j)
        return self.stacked_.means_[:, index], self.stacked_.covariances_[:, index][:, :, index]

    # ----------------------------------------------------------------- fit
    def fit(self, demos, frames):
        """EM on the demonstrations seen from their frames.

        Parameters
        ----------
        demos : list of arrays (T_c, D), world observations [x (P), xdot (P), k (K)].
        frames : list of (A, b) per demonstration: A (F, P, P) rotations, b (F, P) origins,
            the same F for every demonstration.

        Returns
        -------
        self
        """
        check_parameters(self)
        demos = check_demos(demos)
        frames = list(frames)
        if len(frames) != len(demos):
            raise ValueError(
                f"frames must give (A, b) for each of the {len(demos)} demos, got {len(frames)}"
            )
        n_dims = demos[0].shape[1]
        p = self.n_position or n_dims // 2
        if 2 * p > n_dims:
            raise ValueError(f"n_position = {p} needs D >= {2 * p}, the demos have D = {n_dims}")
        self.n_position_, self.n_stiffness_ = p, n_dims - 2 * p
        checked = [
            check_frames(*pair, n_position=p, name=f"frames of demo {c}")
            for c, pair in enumerate(frames)
        ]
        counts = {len(A) for A, _ in checked}
        if len(counts) != 1:
            raise ValueError(f"every demo needs the same number of frames, got {sorted(counts)}")
        self.n_frames_ = counts.pop()
        stacked = [self.stack(d, A, b) for d, (A, b) in zip(demos, checked, strict=True)]
        settings = dict(self._hsmm_parameters(), n_position=self.n_frames_ * p)
        model = _StackedHSMM(self.n_states, **settings)
        model._block_mask = self._block_mask()
        self.stacked_ = model.fit(stacked)
        return self

    def _check_fitted(self):
        check_fitted(self)

    @property
    def n_iter_(self):
        return self.stacked_.n_iter_

    @property
    def converged_(self):
        return self.stacked_.converged_

    # ---------------------------------------------------------- reproduction
    def at(self, A, b):
        """The HSMM of a placement: each state's frame Gaussians mapped by the new frames
        (A (F, P, P), b (F, P)) and multiplied (Calinon 2016, eq. 8).

        Returns
        -------
        HSMM, fitted: ``means_`` (N, D), ``covariances_`` (N, D, D) in the world; pi, A, the
        durations, ``occupancy_`` and ``max_duration_`` of the TP-HSMM; ``data_range_``: the
        stiffness range of the training data, and for x and xdot the box of the stiffness
        frame's training data mapped by its new frame.
        """
        self._check_fitted()
        p, k, f = self.n_position_, self.n_stiffness_, self.n_frames_
        A, b = check_frames(A, b, n_position=p)
        if len(A) != f:
            raise ValueError(f"the model has {f} task frames, got {len(A)}")
        n_dims = 2 * p + k
        world = []  # per frame: means (N, D_j), covariances, and the world indices they cover
        for j in range(f):
            means, covariances = self.frame_gaussians(j)
            size = means.shape[1]
            T = np.eye(size)
            T[:p, :p] = A[j]
            T[p : 2 * p, p : 2 * p] = A[j]
            offset = np.zeros(size)
            offset[:p] = b[j]
            world.append((means @ T.T + offset, T @ covariances @ T.T, np.arange(size)))
        if f == 1:
            means, covariances, _ = world[0]
        else:
            precision = np.zeros((self.n_states, n_dims, n_dims))
            information = np.zeros((self.n_states, n_dims))
            for means_j, covariances_j, index in world:
                inverse = np.linalg.inv(covariances_j)
                precision[:, index[:, None], index[None, :]] += inverse
                information[:, index] += np.einsum("nde,ne->nd", inverse, means_j)
            covariances = np.linalg.inv(precision)
            covariances = 0.5 * (covariances + np.swapaxes(covariances, 1, 2))
            means = np.einsum("nde,ne->nd", covariances, information)
        model = HSMM(self.n_states, **self._hsmm_parameters())
        source = self.stacked_
        for name in ("startprob_", "transmat_", "duration_means_", "duration_stds_", "occupancy_"):
            setattr(model, name, getattr(source, name).copy())
        model.means_, model.covariances_ = means, covariances
        model.data_range_ = self._data_range(A[-1], b[-1])
        model.max_duration_ = source.max_duration_
        model.log_likelihood_history_ = list(source.log_likelihood_history_)
        model.n_iter_ = getattr(source, "n_iter_", len(model.log_likelihood_history_))
        model.converged_ = getattr(source, "converged_", None)
        return model

    def _data_range(self, A, b):
        """x and xdot: the stiffness frame's training box mapped by (A, b); k as trained."""
        p, f = self.n_position_, self.n_frames_
        box = self.stacked_.data_range_
        x_box = box[:, p * (f - 1) : p * f]
        v_box = box[:, f * p + p * (f - 1) : f * p + p * f]
        corners = np.array(np.meshgrid(*[[0, 1]] * p, indexing="ij")).reshape(p, -1).T
        ranges = []
        for lo_hi, offset in ((x_box, b), (v_box, np.zeros(p))):
            points = lo_hi[corners, np.arange(p)] @ A.T + offset
            ranges.append(np.stack([points.min(axis=0), points.max(axis=0)]))
        return np.hstack([*ranges, box[:, 2 * f * p :]])

    # ----------------------------------------------------------- persistence
    def save(self, path):
        """Write the fitted model (format version 3, the per-frame parameters), atomically."""
        self._check_fitted()
        source = self.stacked_
        settings = dict(
            n_states=self.n_states, parameters=self._hsmm_parameters(), n_frames=self.n_frames_,
            n_position=self.n_position_, n_stiffness=self.n_stiffness_,
        )  # fmt: skip
        extra = dict(kind=np.array(KIND), **learnt_at_array(self))
        save_fitted(path, source, FORMAT_VERSION, settings, **extra)

    @classmethod
    def load(cls, path):
        """Read a model written by :meth:`save`; ValueError naming the file if damaged."""
        path = Path(path)
        arrays = load_npz(path, kind="TP-HSMM model")
        version = arrays.get("format_version")
        if version is None or version.shape != () or int(version) != FORMAT_VERSION:
            raise ValueError(
                f"{path}: TP-HSMM model format version {version}, this code reads "
                f"{FORMAT_VERSION} (fit the model again, e.g. hemg-drake learn)"
            )
        missing = [k for k in (*FITTED, "settings", "max_duration_") if k not in arrays]
        if missing:
            raise ValueError(f"{path}: damaged TP-HSMM model file, missing {missing}")
        try:
            settings = json.loads(str(arrays["settings"]))
            model = cls(settings["n_states"], **settings_of(settings["parameters"]))
            check_parameters(model)
            model.n_frames_ = int(settings["n_frames"])
            model.n_position_ = int(settings["n_position"])
            model.n_stiffness_ = int(settings["n_stiffness"])
        except (TypeError, KeyError, ValueError) as error:  # (JSONDecodeError: ValueError)
            raise ValueError(f"{path}: damaged TP-HSMM model settings ({error})") from None
        stacked = _StackedHSMM(
            model.n_states,
            **dict(model._hsmm_parameters(), n_position=model.n_frames_ * model.n_position_),
        )
        load_fitted(stacked, arrays, path, kind="TP-HSMM")
        stacked._block_mask = model._block_mask()
        if stacked.means_.shape[1] != len(stacked._block_mask):
            raise ValueError(f"{path}: damaged TP-HSMM model file, means_ do not fit the frames")
        model.stacked_ = stacked
        model.learnt_at_ = read_learnt_at(arrays, path)
        return model


def model_format(path):
    """The format version of a model file (2: HSMM, 3: TP-HSMM), or None if unreadable."""
    try:
        version = load_npz(Path(path), kind="model").get("format_version")
    except (OSError, ValueError):
        return None
    return None if version is None or version.shape != () else int(version)


def load_model(path):
    """An HSMM (format 2) or a TaskParameterisedHSMM (format 3) from ``path``."""
    if model_format(path) == FORMAT_VERSION:
        return TaskParameterisedHSMM.load(path)
    return HSMM.load(path)
