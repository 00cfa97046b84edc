"""The HSMM's EM steps in log space (eqs. 5-6): E-step forward-backward, exact M-step.

Functions of a model's public parameters and fitted arrays, which
:meth:`~hemg_drake.learning.hsmm.HSMM.fit` iterates, and the duration densities and log
parameters that the recursions (:mod:`hemg_drake.learning._kernels`) take.
"""

import numpy as np

from hemg_drake.learning import _bound_kernels, _kernels, _segment_kernels, _sum_kernels
from hemg_drake.learning.gmr import gaussian_log_pdf


def _log(x):
    with np.errstate(divide="ignore"):
        return np.log(x)


def normalise_rows(counts, previous):
    """Rows of counts normalised; a row with no counts keeps its previous value."""
    totals = counts.sum(axis=1, keepdims=True)
    return np.where(totals > 0, counts / np.where(totals > 0, totals, 1.0), previous)


def floor_covariances(covariances, scale, reg_covar):
    """Covariances (N, D, D) with eigenvalues floored at ``reg_covar`` in units of ``scale``.

    The exact maximiser of the Gaussian likelihood under Sigma >= reg_covar (per-dimension
    variance ``scale**2``): the floor is applied in standardised units.
    """
    standardised = covariances / np.outer(scale, scale)
    values, vectors = np.linalg.eigh(standardised)
    values = np.maximum(values, reg_covar)
    floored = (vectors * values[:, None, :]) @ np.swapaxes(vectors, 1, 2)
    floored = 0.5 * (floored + np.swapaxes(floored, 1, 2))
    return floored * np.outer(scale, scale)


def log_durations(duration_means, duration_stds, max_duration):
    """log p_i(d) for d = 1 .. d_max, shape (N, d_max); -inf beyond the support.

    The support is |d - mu_i^D| <= 10 sigma_i^D (p below e^-50 of its peak is taken as
    zero), so the recursions cost O(T N sigma) rather than O(T N d_max).
    """
    d = np.arange(1, max_duration + 1)
    z = (d[None, :] - duration_means[:, None]) / duration_stds[:, None]
    log_p = -0.5 * z**2 - np.log(np.sqrt(2.0 * np.pi) * duration_stds)[:, None]
    return np.where(0.5 * z**2 <= _sum_kernels.NEGLIGIBLE, log_p, -np.inf)


def log_parameters(model):
    """log pi, log A and log p_i(d) of a fitted ``model``: what the recursions take."""
    return _log(model.startprob_), _log(model.transmat_), model.log_durations()


def posteriors(log_emission, log_parameters):
    """Forward-backward on one demo's (T, N) emission log-likelihoods.

    Returns the log-likelihood and a dict of state posteriors ``gamma`` (T, N) and the
    expected ``starts``, ``transitions`` and ``durations`` counts (None if impossible).
    """
    log_startprob, log_transmat, log_duration = log_parameters
    log_alpha, log_alpha_in = _kernels.forward(
        log_emission, log_startprob, log_transmat, log_duration
    )
    log_likelihood = np.logaddexp.reduce(log_alpha[-1])
    if not np.isfinite(log_likelihood):
        return log_likelihood, None
    _, _, transitions, duration_counts, starts, ends = _kernels.backward(
        log_emission, log_transmat, log_duration, log_alpha, log_alpha_in, log_likelihood
    )
    return log_likelihood, {
        "gamma": _segment_kernels.occupancy(starts, ends, np.array([0, len(starts)])),
        "starts": starts[0],
        "transitions": transitions,
        "durations": duration_counts,
    }


def expectation(model, demos, outer=None, guesses=None):
    """E-step over all demos; ``outer``: their samples' x x^T as rows (T, D^2), if known.

    One compiled call runs every demonstration's forward-backward pass
    (:func:`_kernels.expectation`): per demonstration in Python, the calls and their
    bookkeeping cost about as much as the emissions on LASA-sized sets. ``guesses``: each
    demonstration's log-likelihood under the previous parameters (the previous E-step's
    ``stats["sequences"]``), with which the passes leave out the segments whose paths carry
    less than e^-50 of it; None keeps every path.
    """
    n = model.n_states
    samples = demos[0] if len(demos) == 1 else np.concatenate(demos)
    bounds = np.concatenate([[0], np.cumsum([len(d) for d in demos])])
    log_emission = gaussian_log_pdf(samples, model.means_, model.covariances_)
    parameters = log_parameters(model)
    if guesses is None:
        guesses = np.full(len(demos), -np.inf)
        suffix = (np.zeros((0, 0)), np.zeros((0, 0)))  # not read
    else:
        suffix = _bound_kernels.suffix_bound(log_emission, bounds, *parameters[1:])
    log_likelihood, sequences, starts, ends, transitions, durations = _kernels.expectation(
        log_emission, bounds, *parameters, guesses, *suffix
    )
    stats = {
        "log_likelihood": log_likelihood,
        "sequences": sequences,
        "starts": starts[bounds[:-1]].sum(axis=0),
        "transitions": transitions,
        "durations": durations,
    }
    if not np.isfinite(log_likelihood):
        return stats
    gamma = _segment_kernels.occupancy(starts, ends, bounds)
    n_dims = samples.shape[1]
    if outer is None:
        outer = (samples[:, :, None] * samples[:, None, :]).reshape(len(samples), -1)
    stats["weight"] = gamma.sum(axis=0)
    stats["sum"] = gamma.T @ samples
    stats["outer"] = (gamma.T @ outer).reshape(n, n_dims, n_dims)  # one matrix product
    return stats


def maximisation(model, stats, scale):
    """M-step: the model's fitted arrays from the E-step's ``stats``, in place.

    Covariances go through ``model.floor_covariances``; duration spreads are floored at
    ``model.min_duration_std_``; states with no mass keep their parameters.
    """
    weight = stats["weight"]
    used = weight > 1e-10 * weight.sum()
    means = stats["sum"][used] / weight[used, None]
    covariances = stats["outer"][used] / weight[used, None, None] - np.einsum(
        "nd,ne->nde", means, means
    )
    model.means_[used] = means
    model.covariances_[used] = model.floor_covariances(covariances, scale)
    model.startprob_ = stats["starts"] / stats["starts"].sum()
    model.transmat_ = normalise_rows(stats["transitions"], model.transmat_)
    counts = stats["durations"]
    total = counts.sum(axis=1)
    has = total > 0
    d = np.arange(1, model.max_duration_ + 1)
    mean = counts[has] @ d / total[has]
    variance = (counts[has] * (d[None, :] - mean[:, None]) ** 2).sum(axis=1) / total[has]
    model.duration_means_[has] = mean
    model.duration_stds_[has] = np.maximum(np.sqrt(variance), model.min_duration_std_)
    model.occupancy_ = weight / weight.sum()
