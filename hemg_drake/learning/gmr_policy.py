"""The paper's reproduction step: HSMM-GMR (eqs. 12-18), one step at a time.

:class:`HsmmGmrPolicy` (``tracker="gmr"`` of :func:`hemg_drake.learning.reproduce.
reproduce` and of the Drake reproducer): one step, from the current position x_t and the
predicted forward variable:

1. state weights h_t (eq. 12), by one of three weightings:
   ``"temporal"`` the forward variable without observation (timing alone);
   ``"spatial"``  h_i proportional to pi_i N(x_t | mu_i^x, S_i^xx) (eq. 14);
   ``"forward"``  the forward variable observing x_t (eqs. 11, 13);
2. [xdot*; k*] = sum_i h_i [mu_i^O + S_i^OI (S_i^II)^-1 (x_t - mu_i^I)] (eqs. 15-17),
   plus, with ``restoring_gain`` kappa > 0, the cross-track attractor
   kappa sum_i h_i (I - w_i u_i u_i^T) (mu_i^x - x_t) added to xdot*, and k* clipped to the
   stiffness range of the training data (``HSMM.data_range_``);
3. x*_{t+1} = x*_t + dt xdot* (eq. 18).

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

Modelling choices (the LQR tracker's weights too). The forward variable is kept in its
residual-duration form (Yu 2010; Calinon's pbdlib ``demo_HSMM``): alpha[i, d] = p(state i
active at t with d steps left, observations so far), normalised each step, so h_i = sum_d
alpha[i, d] is the probability that state i is active (eq. 11 is its d = 1 column) and
nothing underflows. The spatial prior pi_i is the state occupancy of the training data
(``HSMM.occupancy_``), not the HSMM's initial distribution, which is one-hot for a left-to-
right task and would pin eq. 14 to the first state. A state the model never leaves (a zero
row of A) is re-entered when its segment ends, so the final state holds after the task. If
an observation is impossible under every predicted state, that step's weights fall back to
the prediction without the observation.

The defaults of every reproducer (numpy and Drake) are defined once: the shared ones and
the GMR step's here, the LQR tracker's in :mod:`hemg_drake.learning.lqr_policy`.
"""

import warnings

import numpy as np

from hemg_drake.learning.forward import ResidualForward
from hemg_drake.learning.gmr import Gmr, softmax

WEIGHTINGS = ("temporal", "spatial", "forward")
# The defaults shared by every reproducer (numpy and Drake), and the GMR step's.
DEFAULT_DT = 0.01
DEFAULT_WEIGHTING = "forward"
DEFAULT_RESTORING_GAIN = 0.0
# A state moving slower than STILL ** 0.5 times the fastest state counts as half still.
STILL = 0.05
# Eq. 16 integrated by eq. 18 grows a deviation inside state i as exp(lambda t), lambda the
# largest real part of the eigenvalues of S_i^xdot,x (S_i^xx)^-1. Measured on 70 cotter-pin
# reproductions, temporal weighting (docs/reproduction.md): all 8 that diverged (15-98 mm
# after DTW) had a state at 14-30 1/s; none of the 59 below 3.5 1/s went beyond 8.1 mm.
UNSTABLE_RATE = 10.0
# GMR's support: each state conditions on the input clipped onto its SUPPORT_RADIUS-sigma
# ellipsoid (hemg_drake.learning.gmr.Gmr's support_radius), so eq. 16 does not extrapolate
# from a start far from the demonstrations (issue 23: 4 cm beside the pin's ring, eq. 16 sent
# k* to K_max and x* 11 cm up at t = 0). Measured in docs/reproduction.md ("Starts").
SUPPORT_RADIUS = 3.0


def check_position(x, n_position, name):
    """``x`` as a float array of shape (``n_position``,), or a ValueError naming ``name``."""
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


def output_gmr(model):
    """GMR of [xdot, k] given x over the model's states (eqs. 14-17), each state conditioned
    within SUPPORT_RADIUS sigma of its mean, and the training data's stiffness range (k* is
    clipped to it)."""
    gmr = Gmr(
        priors=model.occupancy_,
        means=model.means_,
        covariances=model.covariances_,
        input_dims=model.position_dims_,
        output_dims=np.concatenate([model.velocity_dims_, model.stiffness_dims_]),
        support_radius=SUPPORT_RADIUS,
    ).fit()
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
        self.gmr, self.stiffness_range = output_gmr(model)
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
        return check_position(x, self.n_position, name)

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
        if self.weighting == "spatial":
            h = softmax(self.gmr.log_priors_ + self.gmr.log_input_likelihood(x))
            predicted_next = predicted
        else:
            if self.weighting == "forward":
                log_emission = self.gmr.log_input_likelihood(x)
            else:
                log_emission = np.zeros(self.n_states)
            h, predicted_next = self.forward.step(predicted, log_emission)
        output = h @ self.gmr.component_means(x)
        xdot = output[: self.n_position]
        if self.restoring_gain > 0:
            towards = self.gmr.input_means_ - x  # (N, P)
            xdot = xdot + self.restoring_gain * np.einsum(
                "n,npq,nq->p", h, self.cross_track, towards
            )
        k = np.clip(output[self.n_position :], *self.stiffness_range)
        return h, xdot, k, x_star + self.dt * xdot, predicted_next
