"""The HSMM's compiled kernels outside the log-space time recursions, compiled by numba.

The squared Mahalanobis distances of the Gaussian emissions (GMR, and every E-step's
emissions) and one step of the residual-duration forward recursion in probability space,
normalised (reproduction). Neither calls the kernels of :mod:`hemg_drake.learning._kernels`:
numba's on-disk cache (``cache=True``) notices changes to a kernel's own file only.
"""

import numba
import numpy as np

# Samples per block of :func:`mahalanobis`: a block's centred samples stay in the L1 cache.
_BLOCK = 256


@numba.njit(cache=True, fastmath={"reassoc", "contract"})
def mahalanobis(x_T, means, inverse_cholesky):
    """Squared Mahalanobis distances |L_i^-1 (x_t - mu_i)|^2, shape (T, N).

    Parameters
    ----------
    x_T : array, shape (D, T)
        The samples, transposed (so that the loops over samples are SIMD).
    means : array, shape (N, D)
    inverse_cholesky : array, shape (N, D, D)
        L_i^-1, lower triangular (only that triangle is read).
    """
    n_dims, n_steps = x_T.shape
    n_states = means.shape[0]
    out = np.empty((n_steps, n_states))
    centred = np.empty((n_dims, _BLOCK))
    white = np.empty(_BLOCK)
    total = np.empty(_BLOCK)
    for start in range(0, n_steps, _BLOCK):
        size = min(_BLOCK, n_steps - start)
        for i in range(n_states):
            for j in range(n_dims):
                for t in range(size):
                    centred[j, t] = x_T[j, start + t] - means[i, j]
            total[:size] = 0.0
            for k in range(n_dims):
                white[:size] = 0.0
                for j in range(k + 1):
                    factor = inverse_cholesky[i, k, j]
                    for t in range(size):
                        white[t] += factor * centred[j, t]
                for t in range(size):
                    total[t] += white[t] * white[t]
            for t in range(size):
                out[start + t, i] = total[t]
    return out


@numba.njit(cache=True)
def residual_step(predicted, log_emission, transmat_T, durations):
    """One step of the residual-duration forward recursion (normalised).

    Parameters
    ----------
    predicted : array, shape (N, n_durations)
        p(state i, d steps left including this one | past), summing to 1.
    log_emission : array, shape (N,)
        log-likelihood of this step's observation per state (zeros: none).
    transmat_T : array, shape (N, N)
        Transposed transition matrix, a_ji at [i, j].
    durations : array, shape (N, n_durations)
        p_i(d).

    Returns
    -------
    h : array, shape (N,)
        p(state i active now | observations), summing to 1. If the
        observation is impossible under every state (or so unlikely that the next
        prediction underflows to zero), the prediction alone.
    predicted_next : array, shape (N, n_durations)
    """
    n_states, n_durations = predicted.shape
    top = log_emission.max()
    weight = np.exp(log_emission - top)
    h = np.empty(n_states)
    predicted_next = np.empty_like(predicted)
    for attempt in range(2):
        if attempt:  # the observation weighed everything to zero: ignore it
            weight[:] = 1.0
        for i in range(n_states):
            h[i] = weight[i] * predicted[i].sum()
        total = h.sum()
        if not total > 0:
            continue
        # Segments ending now (one step left) start the next states; the rest count down.
        starts = transmat_T @ (weight * predicted[:, 0])
        for i in range(n_states):
            for d in range(n_durations - 1):
                predicted_next[i, d] = (
                    weight[i] * predicted[i, d + 1] + starts[i] * durations[i, d]
                )
            predicted_next[i, n_durations - 1] = starts[i] * durations[i, n_durations - 1]
        if predicted_next.sum() > 0:
            break
    return h / total, predicted_next / predicted_next.sum()
