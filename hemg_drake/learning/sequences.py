"""Demonstrations as the HSMM takes them: checked, and hmmlearn's (X, lengths) form; the
layout of an observation xi = [x, xdot, k] and the fitted-model check."""

import numpy as np
from scipy.sparse import issparse
from sklearn.utils.validation import check_is_fitted


def check_fitted(model):
    """Raise ``NotFittedError`` (a ``ValueError``) naming the model if it is not fitted."""
    check_is_fitted(
        model, msg="this %(name)s is not fitted yet: call fit(demos) or %(name)s.load(path)"
    )


def position_count(n_dims, n_position=None):
    """P of the layout xi = [x (P), xdot (P), k (rest)] of D = ``n_dims`` dimensions.

    ``n_position`` if given, else D // 2; ValueError if x and xdot do not fit in D.
    """
    p = n_dims // 2 if n_position is None else n_position
    if 2 * p > n_dims:
        raise ValueError(
            f"n_position = {p} needs D >= {2 * p} (x and xdot), the model has D = {n_dims}"
        )
    return p


def fitted_sequences(model, X, lengths=None):
    """``X`` (and ``lengths``) as checked sequences of a fitted ``model``'s dimension D."""
    return check_demos(split_sequences(X, lengths), n_dims=model.n_dims_)


def check_demos(demos, n_dims=None):
    """Validate demonstrations; return them as a list of float arrays (T_c, D).

    Raises ``ValueError`` naming the demonstration at fault for a wrong shape,
    NaN/inf, a dimension other than ``n_dims`` or the others' dimension.
    """
    if isinstance(demos, np.ndarray) and demos.ndim == 2:
        demos = [demos]
    for c, demo in enumerate([demos] if issparse(demos) else demos):
        if issparse(demo):
            raise ValueError(
                f"demonstration {c + 1} is a sparse matrix: sparse input is not supported, "
                "give a dense array"
            )
        if np.iscomplexobj(demo):
            raise ValueError(f"demonstration {c + 1}: Complex data not supported")
    demos = [np.asarray(demo, dtype=float) for demo in demos]
    if not demos:
        raise ValueError("demos is empty: give at least one array of shape (T, D)")
    for c, demo in enumerate(demos):
        if demo.ndim == 2 and demo.shape[0] >= 1 and demo.shape[1] < 1:
            raise ValueError(
                f"demonstration {c + 1} has 0 feature(s) (shape={demo.shape}) while a "
                "minimum of 1 is required."
            )
        if demo.ndim != 2 or demo.shape[0] < 1:
            raise ValueError(f"demonstration {c + 1} must have shape (T, D), got {demo.shape}")
        if not np.all(np.isfinite(demo)):
            raise ValueError(f"demonstration {c + 1} contains NaN or inf")
        expected = demos[0].shape[1] if n_dims is None else n_dims
        if demo.shape[1] != expected:
            where = "the model's" if n_dims is not None else "demo 0's"
            raise ValueError(
                f"demonstration {c + 1} has D = {demo.shape[1]} dimensions, {where} is D = {expected}"
            )
    return demos


def split_sequences(X, lengths=None):
    """hmmlearn's form to a list: X of shape (sum(lengths), D) cut into ``lengths`` rows.

    Parameters
    ----------
    X : array, shape (n_samples, D), or list of arrays (T_c, D)
        With ``lengths=None`` a 2-D array is one sequence and a list is taken as it is.
    lengths : sequence of int, optional
        Sequence lengths, summing to ``len(X)``.

    Returns
    -------
    list of arrays (T_c, D)
    """
    if lengths is None:
        return [X] if issparse(X) or isinstance(X, np.ndarray) and X.ndim == 2 else list(X)
    X = np.asarray(X, dtype=float)
    lengths = np.asarray(lengths)
    if X.ndim != 2:
        raise ValueError(f"X must have shape (n_samples, D) with lengths, got {X.shape}")
    if (
        lengths.ndim != 1 or lengths.size == 0 or not np.issubdtype(lengths.dtype, np.integer)
        or np.any(lengths < 1) or lengths.sum() != len(X)
    ):  # fmt: skip
        raise ValueError(
            f"lengths must be integers >= 1 summing to len(X) = {len(X)}, got {lengths.tolist()}"
        )
    return np.split(X, np.cumsum(lengths)[:-1])
