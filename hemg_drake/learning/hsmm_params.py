"""The HSMM's constructor parameters: their names and the checks :meth:`HSMM.fit` runs.

scikit-learn's convention: the constructor only stores its arguments; ``fit`` (and
reading a model file) checks them, so ``set_params`` and ``clone`` never raise.
"""

import numpy as np

INITS = ("kmeans", "time", "polyline")


def _integer(value):
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def check_parameters(model):
    """ValueError naming the first constructor parameter of ``model`` out of its range.

    Parameters
    ----------
    model : HSMM or TaskParameterisedHSMM
        Read: ``n_states``, ``max_duration``, ``reg_covar``, ``min_duration_std``,
        ``n_iter``, ``tol``, ``init``, ``n_init``, ``n_position``, ``random_state``.
    """
    if not _integer(model.n_states) or model.n_states < 1:
        raise ValueError(f"n_states must be an integer >= 1, got {model.n_states!r}")
    if model.max_duration is not None and (
        not _integer(model.max_duration) or model.max_duration < 1
    ):
        raise ValueError(f"max_duration must be an integer >= 1, got {model.max_duration!r}")
    if not _number(model.reg_covar) or not model.reg_covar > 0:
        raise ValueError(f"reg_covar must be > 0, got {model.reg_covar!r}")
    if model.min_duration_std is not None and (
        not _number(model.min_duration_std) or not model.min_duration_std > 0
    ):
        raise ValueError(f"min_duration_std must be > 0, got {model.min_duration_std!r}")
    if not _integer(model.n_iter) or model.n_iter < 1:
        raise ValueError(f"n_iter must be an integer >= 1, got {model.n_iter!r}")
    if not _number(model.tol) or not model.tol >= 0:
        raise ValueError(f"tol must be >= 0, got {model.tol!r}")
    if not isinstance(model.init, str) or model.init not in INITS:
        raise ValueError(f"init must be one of {INITS}, got {model.init!r}")
    if not _integer(model.n_init) or model.n_init < 1:
        raise ValueError(f"n_init must be an integer >= 1, got {model.n_init!r}")
    if model.n_position is not None and (not _integer(model.n_position) or model.n_position < 1):
        raise ValueError(f"n_position must be an integer >= 1, got {model.n_position!r}")
    if not _integer(model.random_state) or model.random_state < 0:
        raise ValueError(
            f"random_state must be an integer >= 0 (every draw takes a seed), got "
            f"{model.random_state!r}"
        )


def _number(value):
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
