"""A fitted HSMM's file: NPZ with a format version, written atomically, checked on reading."""

import json
from pathlib import Path

import numpy as np

from hemg_drake.fileio import load_npz, save_npz_atomic

# Version 2 added data_range_ (reproduction clips the stiffness to it).
FORMAT_VERSION = 2

# The fitted parameters (every one is saved).
_FITTED = (
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
        **{name: getattr(model, name) for name in _FITTED},
    )


class PersistenceMixin:
    """:meth:`save` and :meth:`load` of :class:`~hemg_drake.learning.hsmm.HSMM`."""

    def save(self, path):
        """Write the fitted model to ``path`` (NPZ with a format version), atomically."""
        self._check_fitted()
        save_fitted(path, self, FORMAT_VERSION, self.get_params())

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
        missing = [k for k in (*_FITTED, "settings", "max_duration_") if k not in arrays]
        if missing:
            raise ValueError(f"{path}: damaged HSMM model file, missing {missing}")
        try:
            model = cls(**json.loads(str(arrays["settings"])))
        except (TypeError, json.JSONDecodeError) as error:
            raise ValueError(f"{path}: damaged HSMM model settings ({error})") from None
        for name in _FITTED:
            setattr(model, name, arrays[name].astype(float))
        model.max_duration_ = int(arrays["max_duration_"])
        history = arrays.get("log_likelihood_history_", np.empty(0))  # optional: [] if absent
        model.log_likelihood_history_ = history.tolist()
        model.n_iter_ = len(model.log_likelihood_history_)
        model.converged_ = None
        model._check_loaded(path)
        return model

    def _check_loaded(self, path):
        n = self.n_states
        n_dims = self.means_.shape[1] if self.means_.ndim == 2 else -1
        shapes = {
            "startprob_": (n,), "transmat_": (n, n), "means_": (n, n_dims),
            "covariances_": (n, n_dims, n_dims), "duration_means_": (n,),
            "duration_stds_": (n,), "occupancy_": (n,), "data_range_": (2, n_dims),
        }  # fmt: skip
        for name, shape in shapes.items():
            value = getattr(self, name)
            if value.shape != shape:
                raise ValueError(
                    f"{path}: damaged HSMM model file, {name} has shape {value.shape}, "
                    f"expected {shape}"
                )
            if not np.all(np.isfinite(value)):
                raise ValueError(f"{path}: damaged HSMM model file, {name} holds NaN or inf")
        try:
            np.linalg.cholesky(self.covariances_)
        except np.linalg.LinAlgError:
            raise ValueError(
                f"{path}: damaged HSMM model file, covariances_ not positive definite"
            ) from None
        if np.any(self.data_range_[0] > self.data_range_[1]):
            raise ValueError(f"{path}: damaged HSMM model file, data_range_ minimum > maximum")
        if np.any(self.duration_stds_ <= 0) or self.max_duration_ < 1:
            raise ValueError(f"{path}: damaged HSMM model file, bad duration parameters")
