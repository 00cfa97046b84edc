"""The tracking reproduction step: a receding-horizon LQR over the HSMM's predicted states.

:class:`HsmmLqrPolicy` (``tracker="lqr"`` of :func:`hemg_drake.learning.reproduce.
reproduce` and of the Drake reproducer; the Riccati recursions are in
:mod:`hemg_drake.learning.lqr`): a receding-horizon LQR on a task-space double integrator
whose cost over the next H steps is each predicted state's precision over [x, xdot]
weighted by h (minimal intervention, Calinon 2016); x* is the plan's next state, so errors
are fed back, not integrated. k* is the GMR step's (:mod:`hemg_drake.learning.gmr_policy`).
"""

import numpy as np

from hemg_drake.learning import lqr
from hemg_drake.learning.forward import ResidualForward
from hemg_drake.learning.gmr_policy import (
    DEFAULT_DT,
    DEFAULT_WEIGHTING,
    check_position,
    output_gmr,
)

# The LQR tracks a sequence of states over time: the spatial weighting predicts none.
LQR_WEIGHTINGS = ("temporal", "forward")
# Receding horizon of the LQR, steps (1 s at 0.01 s): several of its time constants (0.03-0.2 s
# for the states of the tasks here), so the plan's first step is that of a longer horizon.
DEFAULT_HORIZON = 100
# r of R = r I, s^4/m^2 (scales with the square of the position unit). An axis whose
# position precision is 1/sigma^2 and whose velocity is free gets the natural frequency
# (1 / (sigma^2 r))^(1/4): 32 rad/s where the demonstrations agree to 1 mm, 10 rad/s at
# 1 cm, 5.8 rad/s at 3 cm (docs/reproduction.md, "Trackers").
DEFAULT_CONTROL_COST = 1.0
# The LQR's cost at each step: the most probable state's quadratic form ("active", pbdlib's
# state sequence), or all states' weighted by h ("mixture"; docs/reproduction.md).
STATE_COSTS = ("active", "mixture")
DEFAULT_STATE_COST = "active"
# How far the online tracker's plan may lead the measured tool point, m (HsmmLqrReproducer):
# an arm held back gets a reference at most this far ahead, so the PD pulls with about its
# task-space stiffness times this (about 100 N at K = 145 on the cotter pin) and x* cannot
# run away. 0 re-plans from the measured point itself (docs/reproduction.md, "Trackers").
DEFAULT_MAX_LEAD = 0.02


class HsmmLqrPolicy:
    """One step of the tracking reproduction: an LQR over the HSMM's predicted state sequence.

    The robot is a task-space double integrator, state s = [x, xdot], control the
    acceleration u (:mod:`hemg_drake.learning.lqr`). At step t the HSMM gives the weights
    h_{t+j} of its states over the next H steps (``"temporal"``: the forward variable without
    observation, fixed by the timing; ``"forward"``: observing x_t, then predicted without
    observation), and the LQR minimises over that horizon

        sum_j sum_i w_{t+j,i} (s_{t+j} - mu_i)^T Lambda_i (s_{t+j} - mu_i) + r |u_{t+j}|^2,

    w = h (``state_cost="mixture"``) or the one-hot of the most probable state
    (``"active"``, the state sequence of pbdlib's HSMM + LQR), Lambda_i the inverse of state
    i's [x, xdot] covariance block, mu_i its [x, xdot] mean:
    stiff where the demonstrations agree, free where they vary (minimal intervention,
    Calinon 2016). For a given x, the state's term is least at GMR's conditional velocity
    mu_i^xdot + S_i^xdot,x (S_i^xx)^-1 (x - mu_i^x) (eq. 16), so the LQR tracks eq. 16's
    velocity field with a position pull set by the conditional precision of x. The first
    control is applied: s_{t+1} = A s_t + B u_t. k* is GMR's conditional stiffness at the
    observed position with the weights h_t (eqs. 15-17 for k alone), clipped to the
    training data's range.

    With ``"temporal"`` the sequence does not depend on the motion, so the first-step gains
    of every horizon are computed ahead (batched Riccati recursions over chunks of
    horizons) and a step is u_t = k_t - K_t s_t. The table runs until the weights have not
    changed (by 1e-12) for d_max + H steps (a left-to-right model then holds its last
    state), and later steps use its last horizon; a model that has not settled by twice its
    expected length (loops in A) gets further chunks when a step needs them. With
    ``"forward"`` each step predicts H steps of weights and runs the H-step recursion.

    Parameters
    ----------
    model : HSMM
        Fitted.
    weighting : {"temporal", "forward"}
    dt : float
        Step in s.
    horizon : int
        H, in steps (>= 1).
    control_cost : float
        r of R = r I in s^4/m^2 (model units: s^4 per position unit squared), > 0.
    state_cost : {"active", "mixture"}
    """

    CHUNK = 256  # horizons per batched Riccati recursion of the temporal table

    def __init__(
        self,
        model,
        *,
        weighting=DEFAULT_WEIGHTING,
        dt=DEFAULT_DT,
        horizon=DEFAULT_HORIZON,
        control_cost=DEFAULT_CONTROL_COST,
        state_cost=DEFAULT_STATE_COST,
    ):
        if weighting not in LQR_WEIGHTINGS:
            raise ValueError(
                f"weighting must be one of {LQR_WEIGHTINGS} with tracker='lqr' (the spatial "
                f"weighting predicts no state sequence), got {weighting!r}"
            )
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a finite number > 0, got {dt!r}")
        if not isinstance(horizon, (int, np.integer)) or isinstance(horizon, bool) or horizon < 1:
            raise ValueError(f"horizon must be an integer >= 1 (steps), got {horizon!r}")
        if not (np.isfinite(control_cost) and control_cost > 0):
            raise ValueError(f"control_cost must be a finite number > 0, got {control_cost!r}")
        if state_cost not in STATE_COSTS:
            raise ValueError(f"state_cost must be one of {STATE_COSTS}, got {state_cost!r}")
        self.state_cost = state_cost
        model.check_weighting(weighting)  # warns where the combination is known to fail
        self.forward = ResidualForward(model)
        self.weighting = weighting
        self.dt = float(dt)
        self.horizon = int(horizon)
        self.control_cost = float(control_cost)
        self.n_position = p = len(model.position_dims_)
        self.n_stiffness = len(model.stiffness_dims_)
        self.n_states = model.n_states
        dims = np.concatenate([model.position_dims_, model.velocity_dims_])
        block = model.covariances_[np.ix_(range(self.n_states), dims, dims)]
        precisions = np.linalg.inv(block)
        self.precisions = 0.5 * (precisions + np.swapaxes(precisions, 1, 2))
        self.informations = np.einsum("nij,nj->ni", self.precisions, model.means_[:, dims])
        self.A, self.B = lqr.double_integrator(p, self.dt)
        self.R = self.control_cost * np.eye(p)
        self.gmr, self.stiffness_range = output_gmr(model)
        self._zeros = np.zeros(self.n_states)
        if weighting == "temporal":
            self._max_duration = model.max_duration_
            self._h_table = np.empty((0, self.n_states))
            self._gain_table = np.empty((0, p, 2 * p))
            self._feedforward_table = np.empty((0, p))
            self._table_predicted, self._table_still = self.forward.initial(), 0
            self._table_done = False
            # Until the timing alone has settled (a left-to-right model), at most 2 tasks long.
            expected = 2 * int(np.sum(model.duration_means_)) + model.max_duration_
            while not self._table_done and len(self._gain_table) < expected:
                self._temporal_table(self._max_duration)

    def costs(self, h):
        """Q = sum_i w_i Lambda_i, shape (..., 2P, 2P), and Q m = sum_i w_i Lambda_i mu_i.

        w = h (``"mixture"``) or the one-hot of argmax h (``"active"``); h of shape (..., N).
        """
        if self.state_cost == "active":
            active = np.argmax(h, axis=-1)
            return self.precisions[active], self.informations[active]
        return np.tensordot(h, self.precisions, 1), h @ self.informations

    def predict_weights(self, predicted, n_steps):
        """Weights h of the next ``n_steps`` steps without observation, shape (n_steps, N)."""
        h = np.empty((n_steps, self.n_states))
        for j in range(n_steps):
            h[j], predicted = self.forward.step(predicted, self._zeros)
        return h

    def _temporal_table(self, max_duration):
        """Weights and first-step gains of the timing alone, for the horizons t0 .. t0 + CHUNK.

        Extended chunk by chunk (always the same chunks, so the numbers do not depend on how
        far a rollout went) until the weights have stayed within 1e-12 for d_max + H + 2
        steps: no segment can outlast d_max, so they are settled, and the last horizon
        lies in the settled part.
        """
        if self._table_done:
            return
        start = len(self._gain_table)
        need = start + self.CHUNK + self.horizon + 1  # weights of the chunk's horizons
        h = list(self._h_table)
        while len(h) < need:
            weights, self._table_predicted = self.forward.step(self._table_predicted, self._zeros)
            if h and np.max(np.abs(weights - h[-1])) <= 1e-12:
                self._table_still += 1
            else:
                self._table_still = 0
            h.append(weights)
        self._h_table = np.array(h)
        Q, Qm = self.costs(self._h_table[start:need])
        # Horizon t is the slice t .. t + H of the sequence (views, no copies).
        windows = np.lib.stride_tricks.sliding_window_view
        Q_windows = np.moveaxis(windows(Q, self.horizon + 1, axis=0), -1, 1)[: self.CHUNK]
        Qm_windows = np.moveaxis(windows(Qm, self.horizon + 1, axis=0), -1, 1)[: self.CHUNK]
        gains, feedforward = lqr.tracking_gains(
            self.A, self.B, Q_windows, Qm_windows, self.R, first_only=True
        )
        self._gain_table = np.concatenate([self._gain_table, gains])
        self._feedforward_table = np.concatenate([self._feedforward_table, feedforward])
        # Constant for d_max steps beyond the last horizon: later horizons repeat the last.
        self._table_done = self._table_still >= max_duration + self.horizon + 2

    def check_position(self, x, name="position"):
        """``x`` as a float array of shape (P,), or a ValueError naming ``name``."""
        return check_position(x, self.n_position, name)

    def step(self, t, x, xdot, predicted, observed=None):
        """One step: the weights at x_t, the plan's first control, the next state.

        Parameters
        ----------
        t : int
            Step index (t dt s since the start).
        x : array, shape (P,)
            Current position of the plan x_t.
        xdot : array, shape (P,)
            Current velocity of the plan xdot_t.
        predicted : array, shape (N, d_max)
            Predicted forward variable for this step (not used by ``"temporal"``).
        observed : array, shape (P,), optional
            The measured position, observed by the forward weighting and input of k*;
            default ``x``.

        Returns
        -------
        h : array, shape (N,)
        k : array, shape (K,)
        x_next, xdot_next : arrays, shape (P,)
            A s_t + B u_t.
        predicted_next : array, shape (N, d_max)
        """
        state = np.concatenate([x, xdot])
        observed = x if observed is None else observed
        if self.weighting == "temporal":
            while t >= len(self._gain_table) and not self._table_done:
                self._temporal_table(self._max_duration)  # a model that has not settled yet
            h = self._h_table[min(t, len(self._h_table) - 1)]
            row = min(t, len(self._gain_table) - 1)
            u = self._feedforward_table[row] - self._gain_table[row] @ state
            predicted_next = predicted
        else:
            log_emission = self.gmr.log_input_likelihood(observed)
            h, predicted_next = self.forward.step(predicted, log_emission)
            ahead = np.concatenate([h[None], self.predict_weights(predicted_next, self.horizon)])
            u = lqr.first_control(self.A, self.B, *self.costs(ahead), self.R, state)
        output = h @ self.gmr.component_means(observed)
        k = np.clip(output[self.n_position :], *self.stiffness_range)
        state_next = self.A @ state + self.B @ u
        return h, k, state_next[: self.n_position], state_next[self.n_position :], predicted_next
