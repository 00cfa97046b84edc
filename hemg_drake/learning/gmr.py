"""Gaussian mixture regression: condition a mixture on a subset of dimensions (eqs. 14-17)."""

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError

from hemg_drake.learning import _step_kernels


def gaussian_log_pdf(x, means, covariances):
    """log N(x | mu_i, Sigma_i) for every sample and component.

    Parameters
    ----------
    x : array, shape (T, D)
    means : array, shape (N, D)
    covariances : array, shape (N, D, D), symmetric positive definite.

    Returns
    -------
    array, shape (T, N)
    """
    return _log_pdf_whitened(x, means, *_whitening(covariances))


def _whitening(covariances):
    """L^-1 of each Cholesky factor, shape (N, D, D), and log det Sigma_i, shape (N,)."""
    cholesky = np.linalg.cholesky(covariances)
    eye = np.broadcast_to(np.eye(covariances.shape[-1]), covariances.shape)
    log_det = 2.0 * np.log(np.diagonal(cholesky, axis1=1, axis2=2)).sum(axis=1)
    return np.linalg.solve(cholesky, eye), log_det


# From this many samples on, the compiled loop beats a batched numpy product.
_COMPILED = 64


def _log_pdf_whitened(x, means, inverse_cholesky, log_det):
    if len(x) >= _COMPILED:  # long batches (EM): 3-4x faster than a matrix product per state
        mahalanobis = _step_kernels.mahalanobis(np.ascontiguousarray(x.T), means, inverse_cholesky)
    else:  # one query or a few (reproduction): one batched product
        diff = x[:, None, :, None] - means[None, :, :, None]  # (T, N, D, 1)
        mahalanobis = np.square(inverse_cholesky @ diff).sum(axis=(2, 3))
    return -0.5 * (mahalanobis + log_det + means.shape[1] * np.log(2.0 * np.pi))


def softmax(log_weights):
    """exp(log_weights) normalised over the last axis, without overflow."""
    shifted = np.exp(log_weights - log_weights.max(axis=-1, keepdims=True))
    return shifted / shifted.sum(axis=-1, keepdims=True)


class Gmr(BaseEstimator):
    """p(xi^O | xi^I) of a Gaussian mixture, for one query or a batch.

    A scikit-learn estimator whose constructor only stores the mixture and the index
    split; :meth:`fit` checks them and precomputes the regression matrices
    S_i^OI (S_i^II)^-1 and the conditional covariances. The mixture is given (e.g. an
    HSMM's ``occupancy_``, ``means_``, ``covariances_``), not learnt from ``X``::

        gmr = Gmr(priors=pi, means=mu, covariances=sigma, input_dims=[0, 1]).fit()
        mean, covariance = gmr.predict(x)

    Parameters
    ----------
    priors : array, shape (N,)
        Mixture weights pi_i (>= 0, summing to 1).
    means : array, shape (N, D)
    covariances : array, shape (N, D, D)
    input_dims : sequence of int
        Indices of xi^I, the dimensions conditioned on.
    output_dims : sequence of int, optional
        Indices of xi^O; default all the others, in order.
    support_radius : float, optional
        r > 0: each state conditions on the input clipped onto its own r-sigma ellipsoid,
        x_i = mu_i^I + min(1, r / d_i) (x - mu_i^I), d_i the Mahalanobis distance
        |x - mu_i^I| in S_i^II (the nearest point of the ellipsoid along the ray from its
        mean). Inside every state's ellipsoid this is eq. 16 exactly; outside, state i's
        linear regression no longer extrapolates beyond what its data supports, and its
        output stays what it is r sigma out. Default None: eq. 16 everywhere.

    Attributes
    ----------
    input_dims_, output_dims_ : arrays of int
        The index split, checked.
    log_priors_ : array, shape (N,)
        log pi_i (-inf for a zero weight).
    input_means_ : array, shape (N, I)
    output_means_ : array, shape (N, O)
    input_covariances_ : array, shape (N, I, I)
    gains_ : array, shape (N, O, I)
        S_i^OI (S_i^II)^-1 (eq. 16).
    conditional_covariances_ : array, shape (N, O, O)
        S_i^OO - S_i^OI (S_i^II)^-1 S_i^IO (eq. 17).
    """

    def __init__(self, *, priors=None, means=None, covariances=None, input_dims=None,
                 output_dims=None, support_radius=None):  # fmt: skip
        self.priors = priors
        self.means = means
        self.covariances = covariances
        self.input_dims = input_dims
        self.output_dims = output_dims
        self.support_radius = support_radius

    def fit(self, X=None, y=None):
        """Check the mixture and the index split; precompute the regression (eqs. 16-17).

        Parameters
        ----------
        X, y : ignored
            The mixture is a parameter; kept for scikit-learn's ``fit`` signature.

        Returns
        -------
        self
        """
        if self.means is None or self.covariances is None or self.priors is None:
            raise ValueError("Gmr needs priors, means and covariances (the mixture)")
        if self.input_dims is None:
            raise ValueError("Gmr needs input_dims, the indices conditioned on")
        means = np.asarray(self.means, dtype=float)
        covariances = np.asarray(self.covariances, dtype=float)
        priors = np.asarray(self.priors, dtype=float)
        n_states, n_dims = means.shape if means.ndim == 2 else (0, 0)
        if means.ndim != 2 or n_states < 1:
            raise ValueError(f"means must have shape (N, D), got {means.shape}")
        if covariances.shape != (n_states, n_dims, n_dims):
            raise ValueError(
                f"covariances must have shape {(n_states, n_dims, n_dims)}, "
                f"got {covariances.shape}"
            )
        if priors.shape != (n_states,) or np.any(priors < 0):
            raise ValueError(f"priors must be {n_states} non-negative weights")
        input_dims = np.asarray(self.input_dims, dtype=int).ravel()
        output_dims = self.output_dims
        if output_dims is None:
            output_dims = np.setdiff1d(np.arange(n_dims), input_dims)
        output_dims = np.asarray(output_dims, dtype=int).ravel()
        both = np.concatenate([input_dims, output_dims])
        if input_dims.size == 0 or np.any((both < 0) | (both >= n_dims)):
            raise ValueError(
                f"input_dims and output_dims must be indices in [0, {n_dims}), "
                f"input_dims non-empty; got {input_dims.tolist()}, {output_dims.tolist()}"
            )
        if np.unique(both).size != both.size:
            raise ValueError("input_dims and output_dims must not overlap")
        radius = self.support_radius
        if radius is not None and not (np.isfinite(radius) and radius > 0):
            raise ValueError(f"support_radius must be None or a finite number > 0, got {radius!r}")
        for name, value in (("means", means), ("covariances", covariances), ("priors", priors)):
            if not np.all(np.isfinite(value)):
                raise ValueError(f"{name} contain NaN or inf")

        self.input_dims_ = input_dims
        self.output_dims_ = output_dims
        self.input_means_ = means[:, input_dims]
        self.output_means_ = means[:, output_dims]
        self.input_covariances_ = covariances[np.ix_(range(n_states), input_dims, input_dims)]
        cross = covariances[np.ix_(range(n_states), output_dims, input_dims)]
        output_cov = covariances[np.ix_(range(n_states), output_dims, output_dims)]
        # gains = S^OI (S^II)^-1, via a solve with the symmetric S^II.
        self.gains_ = np.swapaxes(
            np.linalg.solve(self.input_covariances_, np.swapaxes(cross, 1, 2)), 1, 2
        )
        self.conditional_covariances_ = output_cov - self.gains_ @ np.swapaxes(cross, 1, 2)
        with np.errstate(divide="ignore"):
            self.log_priors_ = np.log(priors)
        self._input_whitening = _whitening(self.input_covariances_)
        return self

    def __sklearn_is_fitted__(self):
        return hasattr(self, "gains_")

    def _as_queries(self, x):
        if not hasattr(self, "gains_"):
            raise NotFittedError("this Gmr is not fitted yet: call fit()")
        x = np.asarray(x, dtype=float)
        n_in = self.input_dims_.size
        if x.shape[-1:] != (n_in,) or x.ndim > 2:
            raise ValueError(f"query must have shape ({n_in},) or (T, {n_in}), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError("query contains NaN or inf")
        return np.atleast_2d(x), x.ndim == 1

    def log_input_likelihood(self, x):
        """log N(x | mu_i^I, S_i^II) per component; shape (T, N) (or (N,) for one query)."""
        queries, single = self._as_queries(x)
        log_pdf = _log_pdf_whitened(queries, self.input_means_, *self._input_whitening)
        return log_pdf[0] if single else log_pdf

    def responsibilities(self, x):
        """h_i proportional to pi_i N(x | mu_i^I, S_i^II) (eq. 14); shape (T, N) or (N,)."""
        return softmax(self.log_priors_ + self.log_input_likelihood(x))

    def component_means(self, x):
        """mu_i^O + S_i^OI (S_i^II)^-1 (x_i - mu_i^I) (eq. 16); shape (T, N, O) or (N, O).

        x_i = x, or with ``support_radius`` r the input clipped onto state i's r-sigma
        ellipsoid."""
        queries, single = self._as_queries(x)
        means = self._component_means(queries)
        return means[0] if single else means

    def _component_means(self, queries):
        diff = queries[:, None, :] - self.input_means_[None]  # (T, N, I)
        if self.support_radius is not None:
            whitened = np.einsum("nij,tnj->tni", self._input_whitening[0], diff)
            distance = np.sqrt(np.square(whitened).sum(axis=2))  # Mahalanobis, (T, N)
            scale = self.support_radius / np.maximum(distance, self.support_radius)
            diff = diff * scale[:, :, None]
        return self.output_means_[None] + np.einsum("noi,tni->tno", self.gains_, diff)

    def predict(self, x, weights=None):
        """Conditional mean and covariance of xi^O given xi^I = x (eqs. 15-17).

        Parameters
        ----------
        x : array, shape (I,) or (T, I)
        weights : array, shape (N,) or (T, N), optional
            State weights h; default the mixture posterior of eq. 14.

        Returns
        -------
        mean : array, shape (O,) or (T, O)
        covariance : array, shape (O, O) or (T, O, O)
            Covariance of the mixture of conditionals (law of total covariance).
        """
        queries, single = self._as_queries(x)
        if weights is None:
            weights = self.responsibilities(queries)
        shape = (len(queries), len(self.log_priors_))
        try:
            weights = np.broadcast_to(np.asarray(weights, dtype=float), shape)
        except ValueError:
            raise ValueError(
                f"weights must have shape ({shape[1]},) or {shape}, got {np.shape(weights)}"
            ) from None
        means = self._component_means(queries)  # (T, N, O)
        mean = np.einsum("tn,tno->to", weights, means)
        spread = means - mean[:, None, :]
        covariance = np.einsum("tn,nop->top", weights, self.conditional_covariances_) + np.einsum(
            "tn,tno,tnp->top", weights, spread, spread
        )
        if single:
            return mean[0], covariance[0]
        return mean, covariance
