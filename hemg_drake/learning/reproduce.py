"""HSMM reproduction: HSMM-GMR (eqs. 12-18) and an LQR tracker of the HSMM's states.

``tracker="gmr"`` (the paper, :class:`HsmmGmrPolicy`): one step, from the current position
x_t and the predicted forward variable:

1. state weights h_t (eq. 12), by one of three weightings:
   ``"temporal"`` the forward variable without observation (timing alone);
   ``"spatial"``  h_i proportional to pi_i N(x_t | mu_i^x, S_i^xx) (eq. 14);
   ``"forward"``  the forward variable observing x_t (eqs. 11, 13);
2. [xdot*; k*] = sum_i h_i [mu_i^O + S_i^OI (S_i^II)^-1 (x_t - mu_i^I)] (eqs. 15-17),
   plus, with ``restoring_gain`` kappa > 0, the cross-track attractor
   kappa sum_i h_i (I - w_i u_i u_i^T) (mu_i^x - x_t) added to xdot*, and k* clipped to the
   stiffness range of the training data (``HSMM.data_range_``);
3. x*_{t+1} = x*_t + dt xdot* (eq. 18).

``tracker="lqr"`` (:class:`HsmmLqrPolicy`, :mod:`hemg_drake.learning.lqr`): a
receding-horizon LQR on a task-space double integrator whose cost over the next H steps is
each predicted state's precision over [x, xdot] weighted by h (minimal intervention,
Calinon 2016); x* is the plan's next state, so errors are fed back, not integrated.

The cross-track attractor. When every demonstration starts at one point, eqs. 15-17 hold
no information on how to return to the path from elsewhere: a start offset is carried
along the whole task. The attractor pulls x_t towards the active states' path, across it
only: u_i is the direction of state i's mean velocity mu_i^xdot (the path's direction
there), so the pull neither fights nor distorts the motion along the path and the timing
is kept. A state that barely moves (a hold) has no direction; its projector fades to the
identity (weight s_i^2 / (s_i^2 + STILL s_max^2) on u_i u_i^T, s_i = |mu_i^xdot|), so it
attracts in every direction. Where one state dominates, an offset across the path decays as
exp(-kappa t): time constant 1 / kappa; kappa = 0 is eqs. 15-18 exactly. Measured
alternatives: the principal direction of S_i^xx instead of mu_i^xdot follows the
covariance floor (``reg_covar``, relative to each axis' spread in the data) rather than the
path when the floor is large, and the drawing then lost its strokes; the minimal-
intervention gain (S_i^xx)^-1 scales with the inverse of the demonstrations' spread
(millimetres) and would need a second tuning constant.

k* is clipped because GMR's linear regression (eq. 16) extrapolates: away from the
training data, or between states, it can return a stiffness outside anything
demonstrated (even a negative one); the clip keeps the reproduced gain a demonstrated one.

Modelling choices. The forward variable is kept in its residual-duration form
(Yu 2010; Calinon's pbdlib ``demo_HSMM``): alpha[i, d] = p(state i active at
t with d steps left, observations so far), normalised each step, so h_i =
sum_d alpha[i, d] is the probability that state i is active (eq. 11 is its
d = 1 column) and nothing underflows. The spatial prior pi_i is the state
occupancy of the training data (``HSMM.occupancy_``), not the HSMM's initial
distribution, which is one-hot for a left-to-right task and would pin eq. 14
to the first state. A state the model never leaves (a zero row of A) is
re-entered when its segment ends, so the final state holds after the task.
If an observation is impossible under every predicted state, that step's
weights fall back to the prediction without the observation.
"""

import warnings
from dataclasses import dataclass

import numpy as np

from hemg_drake.learning import lqr
from hemg_drake.learning.forward import ResidualForward
from hemg_drake.learning.gmr import Gmr, softmax

WEIGHTINGS = ("temporal", "spatial", "forward")
TRACKERS = ("gmr", "lqr")
# The defaults of every reproducer (numpy and Drake), in one place.
DEFAULT_DT = 0.01
DEFAULT_WEIGHTING = "forward"
DEFAULT_RESTORING_GAIN = 0.0
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
# A state moving slower than STILL ** 0.5 times the fastest state counts as half still.
STILL = 0.05
# Eq. 16 integrated by eq. 18 grows a deviation inside state i as exp(lambda t), lambda the
# largest real part of the eigenvalues of S_i^xdot,x (S_i^xx)^-1. Measured on 70 cotter-pin
# reproductions, temporal weighting (docs/reproduction.md): all 8 that diverged (15-98 mm
# after DTW) had a state at 14-30 1/s; none of the 59 below 3.5 1/s went beyond 8.1 mm.
UNSTABLE_RATE = 10.0


def _check_position(x, n_position, name):
    x = np.asarray(x, dtype=float)
    if x.shape != (n_position,):
        raise ValueError(
            f"{name} must have shape ({n_position},) like the model's position, got {x.shape}"
        )
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} contains NaN or inf")
    return x


def regression_growth_rates(model):
    """Per state, the fastest growth rate (1/s) of eq. 16's velocity-on-position regression.

    lambda_i = max Re eig(S_i^{xdot,x} (S_i^{xx})^-1): integrated by eq. 18 with the state
    active alone, a deviation from mu_i^x grows (lambda_i > 0) or decays (< 0) as
    exp(lambda_i t). Returns an array of shape (N,).
    """
    position, velocity = model.position_dims_, model.velocity_dims_
    S = model.covariances_
    gains = S[:, velocity][:, :, position] @ np.linalg.inv(S[:, position][:, :, position])
    return np.linalg.eigvals(gains).real.max(axis=1)


def check_gmr_stability(model, *, limit=UNSTABLE_RATE):
    """Warn (``UserWarning``) if a state's regression makes eqs. 15-18 likely to diverge."""
    rates = regression_growth_rates(model)
    worst = int(np.argmax(rates))
    if rates[worst] > limit:
        warnings.warn(
            f"state {worst}'s velocity regression (eq. 16) grows deviations at "
            f"{rates[worst]:+.1f} 1/s (above {limit:g} 1/s): integrated by eq. 18 the "
            "reproduction can diverge. Use tracker='lqr', fewer states or a larger reg_covar",
            stacklevel=3,
        )
    return rates


def _output_gmr(model):
    """GMR of [xdot, k] given x over the model's states (eqs. 14-17), and the training
    data's stiffness range (k* is clipped to it)."""
    gmr = Gmr(
        priors=model.occupancy_,
        means=model.means_,
        covariances=model.covariances_,
        input_dims=model.position_dims_,
        output_dims=np.concatenate([model.velocity_dims_, model.stiffness_dims_]),
    )
    return gmr, model.data_range_[:, model.stiffness_dims_]


class HsmmGmrPolicy:
    """One reproduction step of a fitted HSMM, shared by :func:`reproduce` and the LeafSystem.

    Parameters
    ----------
    model : HSMM
        Fitted; its layout says which dimensions are x, xdot and k.
    weighting : {"temporal", "spatial", "forward"}
    dt : float
        Step in seconds (eq. 18).
    restoring_gain : float
        kappa of the cross-track attractor in 1/s, >= 0 (0: eqs. 15-18 alone); an offset
        across the path decays with the time constant 1 / kappa. kappa dt must stay below
        1 (explicit Euler, eq. 18).
    """

    def __init__(
        self, model, *, weighting=DEFAULT_WEIGHTING, dt=DEFAULT_DT,
        restoring_gain=DEFAULT_RESTORING_GAIN,
    ):  # fmt: skip
        if weighting not in WEIGHTINGS:
            raise ValueError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a finite number > 0, got {dt!r}")
        if not (np.isfinite(restoring_gain) and 0 <= restoring_gain * dt < 1):
            raise ValueError(
                f"restoring_gain must be finite, >= 0 and < 1 / dt = {1 / dt:g} 1/s, "
                f"got {restoring_gain!r}"
            )
        model.check_weighting(weighting)  # warns where the combination is known to fail
        check_gmr_stability(model)
        self.forward = ResidualForward(model)
        self.weighting = weighting
        self.dt = float(dt)
        self.restoring_gain = float(restoring_gain)
        self.n_position = len(model.position_dims_)
        self.n_stiffness = len(model.stiffness_dims_)
        self.n_states = model.n_states
        self.gmr, self.stiffness_range = _output_gmr(model)
        # Cross-track projectors I - w_i u_i u_i^T, u_i the direction of state i's mean
        # velocity; w_i = s_i^2 / (s_i^2 + STILL s_max^2) with s_i its speed: a state that
        # barely moves (a hold) has no path direction and attracts in every direction.
        velocities = model.means_[:, model.velocity_dims_]
        speeds_squared = np.sum(velocities**2, axis=1)
        weights = speeds_squared / np.maximum(
            speeds_squared + STILL * speeds_squared.max(), np.finfo(float).tiny
        )
        # w_i u_i u_i^T = (w_i / s_i^2) v_i v_i^T
        scaled = weights / np.maximum(speeds_squared, np.finfo(float).tiny)
        self.cross_track = np.eye(self.n_position) - np.einsum(
            "n,np,nq->npq", scaled, velocities, velocities
        )

    def check_position(self, x, name="position"):
        """``x`` as a float array of shape (P,), or a ValueError naming ``name``."""
        return _check_position(x, self.n_position, name)

    def step(self, x, x_star, predicted):
        """One step of eqs. 12-18.

        Parameters
        ----------
        x : array, shape (P,)
            Current position x_t, input of the weights and of GMR.
        x_star : array, shape (P,)
            Current reference x*_t, integrated by eq. 18.
        predicted : array, shape (N, d_max)
            Predicted forward variable for this step.

        Returns
        -------
        h : array, shape (N,)
        xdot : array, shape (P,)
        k : array, shape (K,)
        x_star_next : array, shape (P,)
        predicted_next : array, shape (N, d_max)
        """
        query = x[None, :]
        if self.weighting == "spatial":
            h = softmax(self.gmr._log_priors + self.gmr._log_input_likelihood(query)[0])
            predicted_next = predicted
        else:
            if self.weighting == "forward":
                log_emission = self.gmr._log_input_likelihood(query)[0]
            else:
                log_emission = np.zeros(self.n_states)
            h, predicted_next = self.forward.step(predicted, log_emission)
        output = h @ self.gmr._component_means(query)[0]
        xdot = output[: self.n_position]
        if self.restoring_gain > 0:
            towards = self.gmr.input_means_ - x  # (N, P)
            xdot = xdot + self.restoring_gain * np.einsum(
                "n,npq,nq->p", h, self.cross_track, towards
            )
        k = np.clip(output[self.n_position :], *self.stiffness_range)
        return h, xdot, k, x_star + self.dt * xdot, predicted_next


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
        self.gmr, self.stiffness_range = _output_gmr(model)
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
        return _check_position(x, self.n_position, name)

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
            log_emission = self.gmr._log_input_likelihood(observed[None, :])[0]
            h, predicted_next = self.forward.step(predicted, log_emission)
            ahead = np.concatenate([h[None], self.predict_weights(predicted_next, self.horizon)])
            u = lqr.first_control(self.A, self.B, *self.costs(ahead), self.R, state)
        output = h @ self.gmr._component_means(observed[None, :])[0]
        k = np.clip(output[self.n_position :], *self.stiffness_range)
        state_next = self.A @ state + self.B @ u
        return h, k, state_next[: self.n_position], state_next[self.n_position :], predicted_next


@dataclass(frozen=True)
class Reproduction:
    """A reproduced trajectory, one row per step.

    Attributes
    ----------
    t : array, shape (T,)
        Time in s.
    x : array, shape (T, P)
        Position x*_t (x[0] is the start).
    xdot : array, shape (T, P)
        Velocity xdot*_t (eqs. 15-17).
    k : array, shape (T, K) or None
        Stiffness k*_t, None when the model has no stiffness dimension.
    h : array, shape (T, N)
        State weights.
    """

    t: np.ndarray
    x: np.ndarray
    xdot: np.ndarray
    k: np.ndarray | None
    h: np.ndarray


def reproduce(
    model,
    start,
    n_steps,
    *,
    dt=DEFAULT_DT,
    weighting=DEFAULT_WEIGHTING,
    restoring_gain=DEFAULT_RESTORING_GAIN,
    tracker="gmr",
    horizon=DEFAULT_HORIZON,
    control_cost=DEFAULT_CONTROL_COST,
    state_cost=DEFAULT_STATE_COST,
):
    """Reproduce a task from a start position, step by step.

    ``tracker="gmr"``: the paper's eqs. 12-18, x*_{t+1} = x*_t + dt xdot*_t with xdot* from
    GMR (:class:`HsmmGmrPolicy`). ``tracker="lqr"``: a receding-horizon LQR on a double
    integrator tracks the HSMM's state sequence (:class:`HsmmLqrPolicy`), from rest at
    ``start``. The position observed at each step is the reproduction's own x*_t. k* is
    clipped to the stiffness range of the training data.

    Parameters
    ----------
    model : HSMM
        Fitted.
    start : array, shape (P,)
        x*_0.
    n_steps : int
        Number of steps T >= 1.
    dt : float
        Step in s.
    weighting : {"temporal", "spatial", "forward"}
        ``"spatial"`` is for ``tracker="gmr"`` only.
    restoring_gain : float
        kappa of the cross-track attractor (1/s); see :class:`HsmmGmrPolicy`. ``"gmr"``
        only: the LQR returns to the path by the states' position precision (must be 0).
    tracker : {"gmr", "lqr"}
    horizon : int
        LQR horizon in steps (``"lqr"`` only).
    control_cost : float
        r of the LQR's control cost R = r I, s^4/m^2 (``"lqr"`` only).
    state_cost : {"active", "mixture"}
        The LQR's cost per step: the most probable state's, or all states' weighted by h
        (``"lqr"`` only).

    Returns
    -------
    Reproduction
        With ``"lqr"``, xdot[t] is the plan's velocity at x[t] (x[t + 1] = x[t] + dt xdot[t]
        + dt^2 / 2 u_t), xdot[0] = 0.
    """
    if tracker not in TRACKERS:
        raise ValueError(f"tracker must be one of {TRACKERS}, got {tracker!r}")
    if not isinstance(n_steps, (int, np.integer)) or n_steps < 1:
        raise ValueError(f"n_steps must be an integer >= 1, got {n_steps!r}")
    if tracker == "lqr":
        if restoring_gain != 0:
            raise ValueError(
                "restoring_gain is for tracker='gmr' only (the LQR returns to the path by "
                f"the states' position precision): give 0, got {restoring_gain!r}"
            )
        return _run(
            HsmmLqrPolicy(
                model,
                weighting=weighting,
                dt=dt,
                horizon=horizon,
                control_cost=control_cost,
                state_cost=state_cost,
            ),
            start,
            n_steps,
        )
    policy = HsmmGmrPolicy(model, weighting=weighting, dt=dt, restoring_gain=restoring_gain)
    return _run(policy, start, n_steps)


def _run(policy, start, n_steps):
    """Close the loop of ``policy`` on its own reference for ``n_steps`` (x_k = x*_k)."""
    lqr_policy = isinstance(policy, HsmmLqrPolicy)
    x = policy.check_position(start, "start")
    xdot = np.zeros_like(x)
    positions = np.empty((n_steps, policy.n_position))
    velocities = np.empty_like(positions)
    stiffness = np.empty((n_steps, policy.n_stiffness))
    weights = np.empty((n_steps, policy.n_states))
    predicted = policy.forward.initial()
    for t in range(n_steps):
        positions[t] = x
        if lqr_policy:  # the plan's state [x*, xdot*] steps on; k* at x*
            velocities[t] = xdot
            weights[t], stiffness[t], x, xdot, predicted = policy.step(t, x, xdot, predicted)
        else:  # GMR's xdot* at x*, integrated (eq. 18)
            weights[t], velocities[t], stiffness[t], x, predicted = policy.step(x, x, predicted)
    return Reproduction(
        t=policy.dt * np.arange(n_steps),
        x=positions,
        xdot=velocities,
        k=stiffness if policy.n_stiffness else None,
        h=weights,
    )
