"""HSMM reproduction: HSMM-GMR (eqs. 12-18) and an LQR tracker of the HSMM's states.

Two trackers, each one step at a time, shared with the Drake reproducers
(:mod:`hemg_drake.learning.systems`):

``tracker="gmr"`` (the paper, :class:`HsmmGmrPolicy`, :mod:`hemg_drake.learning.gmr_policy`):
the state weights h_t (eq. 12), [xdot*; k*] by GMR (eqs. 15-17) with an optional cross-track
attractor, x*_{t+1} = x*_t + dt xdot* (eq. 18).

``tracker="lqr"`` (:class:`HsmmLqrPolicy`, :mod:`hemg_drake.learning.lqr_policy`): a
receding-horizon LQR on a task-space double integrator whose cost over the next H steps is
each predicted state's precision over [x, xdot] weighted by h (minimal intervention,
Calinon 2016); x* is the plan's next state, so errors are fed back, not integrated.

:func:`reproduce` closes either loop on its own reference. Every name of the two policy
modules (defaults, weightings, the stability check) is importable from here.
"""

from dataclasses import dataclass

import numpy as np

from hemg_drake.learning.gmr_policy import (  # noqa: F401
    DEFAULT_DT,
    DEFAULT_RESTORING_GAIN,
    DEFAULT_WEIGHTING,
    STILL,
    UNSTABLE_RATE,
    WEIGHTINGS,
    HsmmGmrPolicy,
    check_gmr_stability,
    regression_growth_rates,
)
from hemg_drake.learning.lqr_policy import (  # noqa: F401
    DEFAULT_CONTROL_COST,
    DEFAULT_HORIZON,
    DEFAULT_MAX_LEAD,
    DEFAULT_STATE_COST,
    LQR_WEIGHTINGS,
    STATE_COSTS,
    HsmmLqrPolicy,
)

TRACKERS = ("gmr", "lqr")


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
