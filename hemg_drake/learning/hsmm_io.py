"""A fitted HSMM's file: NPZ with a format version, written atomically, checked on reading.

:func:`save_fitted` and :func:`load_fitted` write and read the fitted arrays that an HSMM
and a task-parameterised HSMM share; :class:`PersistenceMixin` gives
:class:`~hemg_drake.learning.hsmm.HSMM` its ``save`` and ``load``.
"""

import json
from pathlib import Path

import numpy as np

from hemg_drake.fileio import load_npz, save_npz_atomic
from hemg_drake.learning.hsmm_params import check_parameters
from hemg_drake.learning.sequences import check_fitted

# Version 2 added data_range_ (reproduction clips the stiffness to it).
FORMAT_VERSION = 2

# The fitted parameters (every one is saved).
FITTED = (
    "startprob_", "transmat_", "means_", "covariances_",
    "duration_means_", "duration_stds_", "occupancy_", "data_range_",
)  # fmt: skip


def save_fitted(path, model, format_version, settings, **extra):
    """Write a fitted HSMM's arrays, d_max and history with a format version and the
    ``settings`` that rebuild it (JSON), plus ``extra`` arrays, atomically (NPZ)."""
    save_npz_atomic(
        path,
        format_version=np.array(format_version),
        settings=np.array(json.dumps(settings)),
        max_duration_=np.array(model.max_duration_),
        log_likelihood_history_=np.array(model.log_likelihood_history_, dtype=float),
        **extra,
        **{name: getattr(model, name) for name in FITTED},
    )


def settings_of(settings):
    """Saved constructor settings as today's: ``seed`` (files written before the estimator
    took scikit-learn's name) is read as ``random_state``."""
    settings = dict(settings)
    if "seed" in settings:
        settings.setdefault("random_state", settings.pop("seed"))
    return settings


def load_fitted(model, arrays, path, kind="HSMM"):
    """Set an unfitted ``model``'s fitted arrays, d_max and history from a file's
    ``arrays`` and check them; ValueError naming ``path`` (a ``kind`` model) if damaged."""
    missing = [k for k in (*FITTED, "settings", "max_duration_") if k not in arrays]
    if missing:
        raise ValueError(f"{path}: damaged {kind} model file, missing {missing}")
    for name in FITTED:
        setattr(model, name, arrays[name].astype(float))
    model.max_duration_ = int(arrays["max_duration_"])
    history = arrays.get("log_likelihood_history_", np.empty(0))  # optional: [] if absent
    model.log_likelihood_history_ = history.tolist()
    model.n_iter_ = len(model.log_likelihood_history_)
    model.converged_ = None
    _check_loaded(model, path, kind)
    return model


def _check_loaded(model, path, kind):
    n = model.n_states
    n_dims = model.means_.shape[1] if model.means_.ndim == 2 else -1
    shapes = {
        "startprob_": (n,), "transmat_": (n, n), "means_": (n, n_dims),
        "covariances_": (n, n_dims, n_dims), "duration_means_": (n,),
        "duration_stds_": (n,), "occupancy_": (n,), "data_range_": (2, n_dims),
    }  # fmt: skip
    damaged = f"{path}: damaged {kind} model file"
    for name, shape in shapes.items():
        value = getattr(model, name)
        if value.shape != shape:
            raise ValueError(f"{damaged}, {name} has shape {value.shape}, expected {shape}")
        if not np.all(np.isfinite(value)):
            raise ValueError(f"{damaged}, {name} holds NaN or inf")
    try:
        np.linalg.cholesky(model.covariances_)
    except np.linalg.LinAlgError:
        raise ValueError(f"{damaged}, covariances_ not positive definite") from None
    if np.any(model.data_range_[0] > model.data_range_[1]):
        raise ValueError(f"{damaged}, data_range_ minimum > maximum")
    if np.any(model.duration_stds_ <= 0) or model.max_duration_ < 1:
        raise ValueError(f"{damaged}, bad duration parameters")


def learnt_at_array(model):
    """The placements ``model`` was learnt at (``learnt_at_``, JSON-ready, set by
    ``hemg_drake.pipeline.learn``) as the file's ``learnt_at`` entry; none if unset."""
    learnt_at = getattr(model, "learnt_at_", None)
    return {} if learnt_at is None else {"learnt_at": np.array(json.dumps(learnt_at))}


def read_learnt_at(arrays, path):
    """A model file's ``learnt_at`` (JSON), or None: files written before it was stored."""
    if "learnt_at" not in arrays:
        return None
    try:
        return json.loads(str(arrays["learnt_at"]))
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: damaged model file, learnt_at is not JSON ({error})") from None


class PersistenceMixin:
    """:meth:`save` and :meth:`load` of :class:`~hemg_drake.learning.hsmm.HSMM`."""

    def save(self, path):
        """Write the fitted model to ``path`` (NPZ with a format version), atomically."""
        check_fitted(self)
        save_fitted(path, self, FORMAT_VERSION, self.get_params(), **learnt_at_array(self))

    @classmethod
    def load(cls, path):
        """Read a model written by :meth:`save`.

        Raises ``FileNotFoundError`` for a missing file and ``ValueError``
        naming the file for a damaged one or another format version.
        """
        path = Path(path)
        arrays = load_npz(path, kind="HSMM model")
        version = arrays.get("format_version")
        if version is None:
            what = "a dataset (dataset.npz)" if "metadata" in arrays else "another kind of file"
            raise ValueError(
                f"{path}: not an HSMM model: it holds no format version, like {what}; fit "
                f"a model with hemg-drake learn"
            )
        if version.shape != () or int(version) != FORMAT_VERSION:
            raise ValueError(
                f"{path}: HSMM model format version {version}, this code reads "
                f"{FORMAT_VERSION} (fit the model again, e.g. hemg-drake learn)"
            )
        missing = [k for k in (*FITTED, "settings", "max_duration_") if k not in arrays]
        if missing:
            raise ValueError(f"{path}: damaged HSMM model file, missing {missing}")
        try:
            model = cls(**settings_of(json.loads(str(arrays["settings"]))))
            check_parameters(model)
        except (TypeError, ValueError) as error:  # (json.JSONDecodeError is a ValueError)
            raise ValueError(f"{path}: damaged HSMM model settings ({error})") from None
        load_fitted(model, arrays, path).learnt_at_ = read_learnt_at(arrays, path)
        return model
