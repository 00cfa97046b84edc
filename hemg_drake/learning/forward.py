"""The residual-duration forward recursion of a fitted HSMM, one step at a time.

Shared by :meth:`HSMM.forward_variable` and the reproduction (:mod:`hemg_drake.learning.
reproduce`); it lives here so that the model does not import the reproduction.
"""

import numpy as np

from hemg_drake.learning import _step_kernels
from hemg_drake.learning.sequences import check_fitted


class ResidualForward:
    """The residual-duration forward recursion of a fitted HSMM.

    Parameters
    ----------
    model : HSMM
        Fitted.
    """

    def __init__(self, model):
        check_fitted(model)
        self.durations = np.exp(model.log_durations())  # p_i(d), shape (N, d_max)
        transmat = model.transmat_.copy()
        final = transmat.sum(axis=1) == 0
        transmat[final, final] = 1.0
        self.transmat_T = np.ascontiguousarray(transmat.T)
        self.startprob = model.startprob_

    def initial(self):
        """Predicted alpha before the first step, shape (N, d_max)."""
        alpha = self.startprob[:, None] * self.durations
        return alpha / alpha.sum()

    def step(self, predicted, log_emission):
        """Weigh the prediction by the observation; predict the next step.

        Parameters
        ----------
        predicted : array, shape (N, d_max)
        log_emission : array, shape (N,)
            log-likelihood of the current observation under each state
            (zeros: no observation).

        Returns
        -------
        h : array, shape (N,)
        predicted_next : array, shape (N, d_max)
        """
        return _step_kernels.residual_step(
            predicted, log_emission, self.transmat_T, self.durations
        )
