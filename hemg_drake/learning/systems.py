"""The HSMM reproducers (eqs. 12-18, and an LQR tracker) and the tracking force (eq. 23)."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from hemg_drake.learning.reproduce import (
    DEFAULT_CONTROL_COST,
    DEFAULT_DT,
    DEFAULT_HORIZON,
    DEFAULT_MAX_LEAD,
    DEFAULT_RESTORING_GAIN,
    DEFAULT_STATE_COST,
    DEFAULT_WEIGHTING,
    HsmmGmrPolicy,
    HsmmLqrPolicy,
)


class _Reproducer(LeafSystem):
    """What both reproducers share: input ``p_WE``; the state groups x*, xdot*, k*, h and the
    predicted forward variable, updated every ``dt``; the first four as state output ports."""

    def _declare(self, start, xdot, k, h, predicted, dt):
        self._forward_shape = predicted.shape
        self._p_WE_input = self.DeclareVectorInputPort("p_WE", len(start))
        self._x_star_state = self.DeclareDiscreteState(start)
        self._xdot_star_state = self.DeclareDiscreteState(xdot)
        self._k_star_state = self.DeclareDiscreteState(k)
        self._h_state = self.DeclareDiscreteState(h)
        self._forward_state = self.DeclareDiscreteState(predicted.ravel())
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=dt, offset_sec=0.0, update=self._calc_step
        )
        self._x_star_output = self.DeclareStateOutputPort("x_star", self._x_star_state)
        self._xdot_star_output = self.DeclareStateOutputPort("xdot_star", self._xdot_star_state)
        self._k_star_output = self.DeclareStateOutputPort("k_star", self._k_star_state)
        self._h_output = self.DeclareStateOutputPort("h", self._h_state)

    def _store(self, discrete_state, x_star, xdot_star, k_star, h, predicted):
        discrete_state.set_value(self._x_star_state, x_star)
        discrete_state.set_value(self._xdot_star_state, xdot_star)
        discrete_state.set_value(self._k_star_state, k_star)
        discrete_state.set_value(self._h_state, h)
        discrete_state.set_value(self._forward_state, predicted.ravel())


class HsmmGmrReproducer(_Reproducer):
    """Generates the reference x*, xdot*, stiffness k* and state weights h from a fitted HSMM.

    .. pydrake_system::

        name: HsmmGmrReproducer
        input_ports:
        - p_WE
        output_ports:
        - x_star
        - xdot_star
        - k_star
        - h

    Units: m, m/s, the stiffness channel's units (N/m); h is dimensionless.
    Equations 12-18 of the paper, one step of
    :class:`hemg_drake.learning.reproduce.HsmmGmrPolicy` per period: at
    t_k = k dt the system reads ``p_WE`` as the current position x_k (input of
    the weighting and of GMR), then stores h_k, xdot*_k, k*_k and
    x*_{k+1} = x*_k + dt xdot*_k (eq. 18). With ``p_WE`` fed from ``x_star``
    this is exactly :func:`hemg_drake.learning.reproduce.reproduce`, including the
    optional cross-track attractor (``restoring_gain``) and the clip of k* to the
    training data's stiffness range.

    Every output is a state output, so the system has no direct feedthrough
    and ``x_star`` can close a loop. Before the first update, ``xdot_star``,
    ``k_star`` and ``h`` hold the step evaluated at the start position, so the
    stiffness is meaningful from t = 0. The discrete state also holds the
    predicted forward variable (residual-duration form, N x d_max values).

    Parameters
    ----------
    model : HSMM
        Fitted; its layout gives P (position size) and K (stiffness size).
    start : array, shape (P,)
        x*_0 in m.
    dt : float
        Period in s (Table I: 0.01).
    weighting : {"temporal", "spatial", "forward"}
        See :mod:`hemg_drake.learning.reproduce`.
    restoring_gain : float
        kappa of the cross-track attractor in 1/s (0: eqs. 15-18 alone); an offset across
        the demonstrated path decays with the time constant 1 / kappa.
    """

    def __init__(
        self, *, model, start, dt=DEFAULT_DT, weighting=DEFAULT_WEIGHTING,
        restoring_gain=DEFAULT_RESTORING_GAIN,
    ):  # fmt: skip
        LeafSystem.__init__(self)
        self._policy = HsmmGmrPolicy(
            model, weighting=weighting, dt=dt, restoring_gain=restoring_gain
        )
        start = self._policy.check_position(start, "start")
        predicted = self._policy.forward.initial()
        h, xdot, k, _, _ = self._policy.step(start, start, predicted)
        self._declare(start, xdot, k, h, predicted, dt)

    def _calc_step(self, context, discrete_state):
        p_WE = self._policy.check_position(self._p_WE_input.Eval(context), "p_WE")
        x_star = context.get_discrete_state(self._x_star_state).get_value()
        predicted = context.get_discrete_state(self._forward_state).get_value()
        h, xdot, k, x_star_next, predicted_next = self._policy.step(
            p_WE, x_star, predicted.reshape(self._forward_shape)
        )
        self._store(discrete_state, x_star_next, xdot, k, h, predicted_next)


class HsmmLqrReproducer(_Reproducer):
    """Re-plans an LQR over the HSMM's predicted state sequence from the measured tool point.

    .. pydrake_system::

        name: HsmmLqrReproducer
        input_ports:
        - p_WE
        output_ports:
        - x_star
        - xdot_star
        - k_star
        - h

    Units: m, m/s, the stiffness channel's units (N/m); h is dimensionless. The tracking
    alternative to eqs. 15-18 (docs/reproduction.md, "Trackers"): one step of
    :class:`hemg_drake.learning.reproduce.HsmmLqrPolicy` per period. At t_k = k dt the
    system reads the measured ``p_WE``, takes the plan's state s_k = [x_k, xdot*_k], with
    x_k its own x*_k brought within ``max_lead`` of ``p_WE`` (the velocity is the plan's
    own: only the position is measured), plans H steps ahead on the HSMM's weights (eq. 12;
    the weighting observes ``p_WE``) and applies the first acceleration u_k of the double
    integrator: it stores h_k, k*_k (GMR's conditional stiffness at ``p_WE``, eqs. 15-17,
    clipped to the training range) and [x*_{k+1}, xdot*_{k+1}] = A s_k + B u_k. With
    ``p_WE`` fed from ``x_star`` this is exactly
    :func:`hemg_drake.learning.reproduce.reproduce` with ``tracker="lqr"``.

    An arm held back (the cotter pin's detent) gets a reference at most ``max_lead`` +
    dt |xdot*| ahead of it: enough for the PD to pull (about its task-space stiffness times
    ``max_lead``), never a reference that runs away, unlike eq. 18 integrated on a stuck
    position. ``max_lead = 0`` re-plans from the measured point itself: x*_{k+1} - p_WE =
    dt (xdot*_k + xdot*_{k+1}) / 2, a millimetre at the pin's speed, and the pin measured
    stays in (the PD's force on that lead is a few newtons against a 50 N detent).

    With ``weighting="temporal"`` the gains of every horizon are computed in the
    constructor and a step is one affine feedback (about 10 us); with ``"forward"`` each
    step predicts H steps of weights and runs the H-step Riccati recursion (about 2 ms at
    H = 100; ``benchmarks/bench_tracker.py``).

    Every output is a state output (no direct feedthrough). Before the first update
    ``x_star`` is ``start``, ``xdot_star`` zero (the plan starts at rest), and ``k_star``
    and ``h`` those of step 0. The discrete state also holds the predicted forward variable
    and the step index.

    Parameters
    ----------
    model, start, dt
        As for :class:`HsmmGmrReproducer`.
    weighting : {"temporal", "forward"}
        The state sequence: by the timing alone, or the forward variable observing p_WE.
    horizon : int
        H, steps planned ahead (default 100: 1 s at 0.01 s).
    control_cost : float
        r of the control cost R = r I, s^4/m^2 (default 1).
    max_lead : float
        How far the plan may lead the measured ``p_WE``, m (>= 0; default 0.02).
    state_cost : {"active", "mixture"}
        The cost per step: the most probable state's, or all states' weighted by h.
    """

    def __init__(
        self,
        *,
        model,
        start,
        dt=DEFAULT_DT,
        weighting=DEFAULT_WEIGHTING,
        horizon=DEFAULT_HORIZON,
        control_cost=DEFAULT_CONTROL_COST,
        max_lead=DEFAULT_MAX_LEAD,
        state_cost=DEFAULT_STATE_COST,
    ):
        LeafSystem.__init__(self)
        self._policy = HsmmLqrPolicy(
            model,
            weighting=weighting,
            dt=dt,
            horizon=horizon,
            control_cost=control_cost,
            state_cost=state_cost,
        )
        if not (np.isfinite(max_lead) and max_lead >= 0):
            raise ValueError(f"max_lead must be a finite number >= 0 (m), got {max_lead!r}")
        self._max_lead = float(max_lead)
        start = self._policy.check_position(start, "start")
        xdot = np.zeros_like(start)
        predicted = self._policy.forward.initial()
        h, k, _, _, _ = self._policy.step(0, start, xdot, predicted)
        self._declare(start, xdot, k, h, predicted, dt)
        self._step_state = self.DeclareDiscreteState(1)  # index k of the next update

    def _calc_step(self, context, discrete_state):
        p_WE = self._policy.check_position(self._p_WE_input.Eval(context), "p_WE")
        x_star = context.get_discrete_state(self._x_star_state).get_value()
        xdot = context.get_discrete_state(self._xdot_star_state).get_value()
        predicted = context.get_discrete_state(self._forward_state).get_value()
        step = int(context.get_discrete_state(self._step_state).get_value()[0])
        # The plan's position: its own x*_k, kept within max_lead of the measured point.
        lead = x_star - p_WE
        distance = np.linalg.norm(lead)
        if distance > self._max_lead:
            x_star = p_WE + lead * (self._max_lead / distance)
        h, k, x_next, xdot_next, predicted_next = self._policy.step(
            step, x_star, xdot, predicted.reshape(self._forward_shape), observed=p_WE
        )
        self._store(discrete_state, x_next, xdot_next, k, h, predicted_next)
        discrete_state.set_value(self._step_state, [step + 1.0])


class TrackingForce(LeafSystem):
    """The tracking force of the reproduction, a PD on the goal error (eq. 23).

    .. pydrake_system::

        name: TrackingForce
        input_ports:
        - x_star
        - xdot_star
        - x_goal
        output_ports:
        - F_tr

    F_tr = K_ptr (x_g - x*) + K_dtr xdot* (eq. 23), in N, from positions in m
    and velocities in m/s. Evaluated whenever it is read (direct feedthrough,
    no state): it follows the rate of its inputs.

    Parameters
    ----------
    kp : float or array, shape (size,)
        K_ptr in N/m, >= 0 (per axis if an array).
    kd : float or array, shape (size,)
        K_dtr in N s/m, >= 0.
    size : int
        Number of axes (3 for a point in space).
    """

    def __init__(self, *, kp, kd, size=3):
        LeafSystem.__init__(self)
        if not isinstance(size, (int, np.integer)) or size < 1:
            raise ValueError(f"size must be an integer >= 1, got {size!r}")
        self._kp = self._check_gain(kp, "kp", size)
        self._kd = self._check_gain(kd, "kd", size)
        self._x_star_input = self.DeclareVectorInputPort("x_star", size)
        self._xdot_star_input = self.DeclareVectorInputPort("xdot_star", size)
        self._x_goal_input = self.DeclareVectorInputPort("x_goal", size)
        self._F_tr_output = self.DeclareVectorOutputPort("F_tr", size, self._calc_force)

    @staticmethod
    def _check_gain(gain, name, size):
        try:
            gain = np.broadcast_to(np.asarray(gain, dtype=float), (size,)).copy()
        except ValueError:
            raise ValueError(f"{name} must be a scalar or have shape ({size},)") from None
        if not np.all(np.isfinite(gain)) or np.any(gain < 0):
            raise ValueError(f"{name} must be finite and >= 0, got {gain}")
        return gain

    def _calc_force(self, context, output):
        x_star = self._x_star_input.Eval(context)
        xdot_star = self._xdot_star_input.Eval(context)
        x_goal = self._x_goal_input.Eval(context)
        output.SetFromVector(tracking_force(x_star, xdot_star, x_goal, kp=self._kp, kd=self._kd))


def tracking_force(x_star, xdot_star, x_goal, *, kp, kd):
    """F_tr = kp (x_goal - x_star) + kd xdot_star (eq. 23); arrays of shape (..., size)."""
    return kp * (np.asarray(x_goal) - x_star) + kd * np.asarray(xdot_star)
