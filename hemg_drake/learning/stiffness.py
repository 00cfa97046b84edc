"""A full Cartesian stiffness per HSMM state, interpolated on the SPD manifold.

The paper's eq. 20 scales one joint stiffness by the EMG-learnt k*: the same in every
direction. Here the *shape* of a Cartesian stiffness comes from the demonstrations'
variability and its *scale* from k* (the station applies it, :mod:`hemg_drake.control.
impedance`). Per state i (minimal intervention, Calinon 2016: stiff where the
demonstrations agree, compliant where they vary):

    Lambda_i = (S_i^xx)^-1                      the precision of the position in state i
    log Lambda_i = V diag(l) V^T                (eigendecomposition, l = -log eig S_i^xx)
    l <- l - mean(l)                            unit determinant
    l <- clip(l, -log(rho) / 2, +log(rho) / 2)  bounded: largest / smallest eigenvalue
    l <- l - mean(l)                               <= rho (re-centring keeps the spread)
    L_i = V diag(l) V^T                          the state's log-shape (trace 0)

Between states the shape is the weighted log-Euclidean mean (Arsigny et al. 2007) with the
HSMM state weights h_t (eq. 12), never an element-wise mixture of matrices:

    S_hat(h) = expm(sum_i h_i L_i)

S_hat is symmetric positive definite for any real weights (the exponential of a symmetric
matrix), has unit determinant for weights summing to one (trace of the log is zero), and
for weights in the simplex its eigenvalue ratio stays <= rho (the eigenvalues of a convex
combination of symmetric matrices whose spectra lie in [-a, a] lie in [-a, a]). For two
states it is the geodesic of the log-Euclidean metric; for commuting shapes it is also the
affine-invariant geodesic.

Why the position covariance of the state, not a conditional on time: the HSMM's state *is*
the phase, and S_i^xx holds both the spread across demonstrations and the motion along the
path inside the state, so a pull or a stroke comes out compliant along its direction and
stiff across it.
"""

import numpy as np

# Largest ratio of the shape's largest to smallest eigenvalue (rho above).
DEFAULT_MAX_RATIO = 10.0
# How the interpolated shape is scaled: unit determinant (eigenvalues' geometric mean 1), or
# its smallest eigenvalue 1 (the learnt shape only stiffens, from the softest direction up).
NORMALISATIONS = ("determinant", "softest")
DEFAULT_NORMALISATION = "determinant"


def check_max_ratio(max_ratio):
    """``max_ratio`` as a float >= 1, or ValueError naming it."""
    if not (np.isfinite(max_ratio) and max_ratio >= 1.0):
        raise ValueError(f"max_ratio must be a finite number >= 1, got {max_ratio!r}")
    return float(max_ratio)


def state_log_shapes(covariances, max_ratio=DEFAULT_MAX_RATIO):
    """The log-shapes L_i of the states' position precisions (module docstring).

    Parameters
    ----------
    covariances : array, shape (N, P, P), each state's position covariance S_i^xx
        (symmetric positive definite).
    max_ratio : float, rho >= 1.

    Returns
    -------
    array, shape (N, P, P): symmetric, trace 0, eigenvalues in [-log(rho)/2, log(rho)/2].
    """
    max_ratio = check_max_ratio(max_ratio)
    covariances = np.asarray(covariances, dtype=float)
    if covariances.ndim != 3 or covariances.shape[1] != covariances.shape[2]:
        raise ValueError(f"covariances must have shape (N, P, P), got {covariances.shape}")
    values, vectors = np.linalg.eigh(0.5 * (covariances + np.swapaxes(covariances, 1, 2)))
    if not np.all(values > 0):
        raise ValueError("every state's position covariance must be positive definite")
    logs = -np.log(values)  # the precision's log-eigenvalues
    logs -= logs.mean(axis=1, keepdims=True)
    half = 0.5 * np.log(max_ratio)
    logs = np.clip(logs, -half, half)
    logs -= logs.mean(axis=1, keepdims=True)
    return np.einsum("nij,nj,nkj->nik", vectors, logs, vectors)


def log_euclidean_mean(weights, log_shapes, normalisation=None):
    """expm(sum_i w_i L_i): the weighted log-Euclidean mean of the shapes exp(L_i).

    Parameters
    ----------
    weights : array, shape (N,)
    log_shapes : array, shape (N, P, P), symmetric.
    normalisation : None, "determinant" or "softest"
        None: the mean itself; "determinant": divided by its determinant's P-th root;
        "softest": divided by its smallest eigenvalue.

    Returns
    -------
    array, shape (P, P), symmetric positive definite.
    """
    mixed = np.tensordot(np.asarray(weights, dtype=float), log_shapes, axes=1)
    values, vectors = np.linalg.eigh(0.5 * (mixed + mixed.T))
    if normalisation == "determinant":
        values = values - values.mean()
    elif normalisation == "softest":
        values = values - values[0]
    elif normalisation is not None:
        raise ValueError(f"normalisation must be one of {NORMALISATIONS}, got {normalisation!r}")
    mean = (vectors * np.exp(values)) @ vectors.T
    return 0.5 * (mean + mean.T)  # symmetric to the last bit


class SpdStiffness:
    """The stiffness shapes of a fitted HSMM and their interpolation by state weights.

    Parameters
    ----------
    model : HSMM
        Fitted; its position block of each state's covariance gives the shapes.
    max_ratio : float
        rho, the bound on each shape's largest / smallest eigenvalue (>= 1).
    normalisation : {"determinant", "softest"}
        The interpolated shape at unit determinant, or with its smallest eigenvalue 1.

    Attributes
    ----------
    log_shapes : array, shape (N, P, P), L_i (read-only).
    """

    def __init__(self, model, max_ratio=DEFAULT_MAX_RATIO, normalisation=DEFAULT_NORMALISATION):
        if normalisation not in NORMALISATIONS:
            raise ValueError(
                f"normalisation must be one of {NORMALISATIONS}, got {normalisation!r}"
            )
        self.normalisation = normalisation
        position = np.asarray(model.position_dims_)
        block = model.covariances_[:, position][:, :, position]
        self.max_ratio = check_max_ratio(max_ratio)
        self.log_shapes = state_log_shapes(block, self.max_ratio)
        self.log_shapes.flags.writeable = False

    def shape(self, h):
        """S_hat(h), shape (P, P), SPD, normalised, for state weights h (N,)."""
        return log_euclidean_mean(h, self.log_shapes, self.normalisation)
