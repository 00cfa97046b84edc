"""The HSMM reproducers (eqs. 12-18, and an LQR tracker) and the tracking force (eq. 23)."""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import BasicVector_, Diagram, DiagramBuilder, LeafSystem_
from pydrake.systems.primitives import Adder, Gain, MatrixGain
from pydrake.systems.scalar_conversion import TemplateSystem

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
from hemg_drake.learning.stiffness import (
    DEFAULT_MAX_RATIO,
    DEFAULT_NORMALISATION,
    SpdStiffness,
)


def _declare_reproducer(system, T, start, xdot, k, h, predicted, dt):
    """What both reproducers declare: input ``p_WE``; the state groups x*, xdot*, k*, h,
    the predicted forward variable and the stiffness shape S_hat(h) (P x P, row-major;
    :mod:`hemg_drake.learning.stiffness`), updated every ``dt``; all but the forward
    variable as state outputs;
    the numeric parameter ``holding`` (1: every update keeps the state, so the reproducer
    holds x*_0 and k*_0 while the arm settles; 0, the default: it reproduces)."""
    system._forward_shape = predicted.shape
    system._holding = system.DeclareNumericParameter(BasicVector_[T]([0.0]))
    system._p_WE_input = system.DeclareVectorInputPort("p_WE", len(start))
    system._x_star_state = system.DeclareDiscreteState(start)
    system._xdot_star_state = system.DeclareDiscreteState(xdot)
    system._k_star_state = system.DeclareDiscreteState(k)
    system._h_state = system.DeclareDiscreteState(h)
    system._forward_state = system.DeclareDiscreteState(predicted.ravel())
    system._shape_state = system.DeclareDiscreteState(system._stiffness.shape(h).ravel())
    system.DeclarePeriodicDiscreteUpdateEvent(
        period_sec=dt, offset_sec=0.0, update=system._calc_step
    )
    for name, index in (
        ("x_star", system._x_star_state),
        ("xdot_star", system._xdot_star_state),
        ("k_star", system._k_star_state),
        ("h", system._h_state),
        ("stiffness_shape", system._shape_state),
    ):
        system.DeclareStateOutputPort(name, index)


def set_holding(reproducer, context, holding):
    """Make ``reproducer`` (either kind, or a clone) hold its start in ``context`` (its own
    Context), or reproduce: the ``holding`` parameter of :func:`_declare_reproducer`."""
    context.get_mutable_numeric_parameter(0).SetAtIndex(0, 1.0 if holding else 0.0)


def _step_inputs(system, context):
    """What a reproducer's update reads: (p_WE, x*, the predicted forward variable), or None
    while it holds (the update then starts from, and keeps, the current state)."""
    if context.get_numeric_parameter(system._holding).GetAtIndex(0) != 0.0:
        return None
    p_WE = system._policy.check_position(system._p_WE_input.Eval(context), "p_WE")
    x_star = context.get_discrete_state(system._x_star_state).get_value()
    predicted = context.get_discrete_state(system._forward_state).get_value()
    return p_WE, x_star, predicted.reshape(system._forward_shape)


def _store(system, discrete_state, x_star, xdot_star, k_star, h, predicted):
    discrete_state.set_value(system._x_star_state, x_star)
    discrete_state.set_value(system._xdot_star_state, xdot_star)
    discrete_state.set_value(system._k_star_state, k_star)
    discrete_state.set_value(system._h_state, h)
    discrete_state.set_value(system._forward_state, predicted.ravel())
    discrete_state.set_value(system._shape_state, system._stiffness.shape(h).ravel())


@TemplateSystem.define("HsmmGmrReproducer_", T_list=[float, AutoDiffXd])
def HsmmGmrReproducer_(T):
    class Impl(LeafSystem_[T]):
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
            - stiffness_shape

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
        and ``x_star`` can close a loop. A numeric parameter ``holding`` (see
        :func:`set_holding`) freezes the state, so the reproduction diagram can hold x*_0
        and k*_0 while the arm settles in the scene. Before the first update, ``xdot_star``,
        ``k_star`` and ``h`` hold the step evaluated at the start position, so the
        stiffness is meaningful from t = 0. The discrete state also holds the
        predicted forward variable (residual-duration form, N x d_max values). The
        policy is immutable: everything that changes lives in the Context. The system
        clones (Drake's Clone converts double -> AutoDiffXd -> double, so an AutoDiffXd
        instantiation exists; its update runs the policy on floats and is not
        differentiable).

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
            kappa of the cross-track attractor in 1/s (0: eqs. 15-18 alone); an offset
            across the demonstrated path decays with the time constant 1 / kappa.
        stiffness_ratio : float
            rho >= 1, the bound on the stiffness shape's eigenvalue ratio.
        stiffness_normalisation : {"determinant", "softest"}
            The shape at unit determinant, or with its smallest eigenvalue 1.

        ``stiffness_shape`` (P*P, dimensionless, row-major) is S_hat(h_k) =
        expm(sum_i h_k,i L_i), the log-Euclidean mean of the states' normalised
        position precisions (:mod:`hemg_drake.learning.stiffness`): the shape of the
        Cartesian stiffness the station applies with ``reproduction.stiffness: spd``.
        """

        def _construct(
            self, *, model, start, dt=DEFAULT_DT, weighting=DEFAULT_WEIGHTING,
            restoring_gain=DEFAULT_RESTORING_GAIN, stiffness_ratio=DEFAULT_MAX_RATIO,
            stiffness_normalisation=DEFAULT_NORMALISATION,
            converter=None,
        ):  # fmt: skip
            LeafSystem_[T].__init__(self, converter)
            self._arguments = dict(
                model=model, start=start, dt=dt, weighting=weighting,
                restoring_gain=restoring_gain, stiffness_ratio=stiffness_ratio,
                stiffness_normalisation=stiffness_normalisation,
            )  # fmt: skip
            self._stiffness = SpdStiffness(model, stiffness_ratio, stiffness_normalisation)
            self._policy = HsmmGmrPolicy(
                model, weighting=weighting, dt=dt, restoring_gain=restoring_gain
            )
            start = self._policy.check_position(start, "start")
            predicted = self._policy.forward.initial()
            h, xdot, k, _, _ = self._policy.step(start, start, predicted)
            _declare_reproducer(self, T, start, xdot, k, h, predicted, dt)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._arguments, converter=converter)

        def _calc_step(self, context, discrete_state):
            inputs = _step_inputs(self, context)
            if inputs is None:
                return
            h, xdot, k, x_star_next, predicted_next = self._policy.step(*inputs)
            _store(self, discrete_state, x_star_next, xdot, k, h, predicted_next)

    return Impl


HsmmGmrReproducer = HsmmGmrReproducer_[None]


@TemplateSystem.define("HsmmLqrReproducer_", T_list=[float, AutoDiffXd])
def HsmmLqrReproducer_(T):
    class Impl(LeafSystem_[T]):
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
            - stiffness_shape

        Units: m, m/s, the stiffness channel's units (N/m); h is dimensionless. The
        tracking alternative to eqs. 15-18 (docs/reproduction.md, "Trackers"): one step of
        :class:`hemg_drake.learning.reproduce.HsmmLqrPolicy` per period. At t_k = k dt the
        system reads the measured ``p_WE``, takes the plan's state s_k = [x_k, xdot*_k],
        with x_k its own x*_k brought within ``max_lead`` of ``p_WE`` (the velocity is the
        plan's own: only the position is measured), plans H steps ahead on the HSMM's
        weights (eq. 12; the weighting observes ``p_WE``) and applies the first
        acceleration u_k of the double integrator: it stores h_k, k*_k (GMR's conditional
        stiffness at ``p_WE``, eqs. 15-17, clipped to the training range) and
        [x*_{k+1}, xdot*_{k+1}] = A s_k + B u_k. With ``p_WE`` fed from ``x_star`` this is
        exactly :func:`hemg_drake.learning.reproduce.reproduce` with ``tracker="lqr"``.

        An arm held back (the cotter pin's detent) gets a reference at most ``max_lead`` +
        dt |xdot*| ahead of it: enough for the PD to pull (about its task-space stiffness
        times ``max_lead``), never a reference that runs away, unlike eq. 18 integrated on
        a stuck position. ``max_lead = 0`` re-plans from the measured point itself:
        x*_{k+1} - p_WE = dt (xdot*_k + xdot*_{k+1}) / 2, a millimetre at the pin's speed.

        With ``weighting="temporal"`` the gains of every horizon are computed in the
        constructor and a step is one affine feedback (about 10 us); with ``"forward"``
        each step predicts H steps of weights and runs the H-step Riccati recursion (about
        2 ms at H = 100; ``benchmarks/bench_tracker.py``).

        Every output is a state output (no direct feedthrough). Before the first update
        ``x_star`` is ``start``, ``xdot_star`` zero (the plan starts at rest), and
        ``k_star`` and ``h`` those of step 0. The discrete state also holds the predicted
        forward variable and the step index. Clones, and holds with ``holding``, as
        :class:`HsmmGmrReproducer`.

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
        stiffness_ratio, stiffness_normalisation
            As for :class:`HsmmGmrReproducer` (so is ``stiffness_shape``).
        """

        def _construct(
            self, *, model, start, dt=DEFAULT_DT, weighting=DEFAULT_WEIGHTING,
            horizon=DEFAULT_HORIZON, control_cost=DEFAULT_CONTROL_COST,
            max_lead=DEFAULT_MAX_LEAD, state_cost=DEFAULT_STATE_COST,
            stiffness_ratio=DEFAULT_MAX_RATIO,
            stiffness_normalisation=DEFAULT_NORMALISATION, converter=None,
        ):  # fmt: skip
            LeafSystem_[T].__init__(self, converter)
            self._arguments = dict(
                model=model, start=start, dt=dt, weighting=weighting, horizon=horizon,
                control_cost=control_cost, max_lead=max_lead, state_cost=state_cost,
                stiffness_ratio=stiffness_ratio,
                stiffness_normalisation=stiffness_normalisation,
            )  # fmt: skip
            self._stiffness = SpdStiffness(model, stiffness_ratio, stiffness_normalisation)
            self._policy = HsmmLqrPolicy(
                model, weighting=weighting, dt=dt, horizon=horizon,
                control_cost=control_cost, state_cost=state_cost,
            )  # fmt: skip
            if not (np.isfinite(max_lead) and max_lead >= 0):
                raise ValueError(f"max_lead must be a finite number >= 0 (m), got {max_lead!r}")
            self._max_lead = float(max_lead)
            start = self._policy.check_position(start, "start")
            xdot = np.zeros_like(start)
            predicted = self._policy.forward.initial()
            h, k, _, _, _ = self._policy.step(0, start, xdot, predicted)
            _declare_reproducer(self, T, start, xdot, k, h, predicted, dt)
            self._step_state = self.DeclareDiscreteState(1)  # index k of the next update

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._arguments, converter=converter)

        def _calc_step(self, context, discrete_state):
            inputs = _step_inputs(self, context)
            if inputs is None:
                return
            p_WE, x_star, predicted = inputs
            xdot = context.get_discrete_state(self._xdot_star_state).get_value()
            step = int(context.get_discrete_state(self._step_state).get_value()[0])
            # The plan's position: its own x*_k, kept within max_lead of the measured point.
            lead = x_star - p_WE
            distance = np.linalg.norm(lead)
            if distance > self._max_lead:
                x_star = p_WE + lead * (self._max_lead / distance)
            h, k, x_next, xdot_next, predicted_next = self._policy.step(
                step, x_star, xdot, predicted, observed=p_WE
            )
            _store(self, discrete_state, x_next, xdot_next, k, h, predicted_next)
            discrete_state.set_value(self._step_state, [step + 1.0])

    return Impl


HsmmLqrReproducer = HsmmLqrReproducer_[None]


def _check_gain(gain, name, size):
    try:
        gain = np.broadcast_to(np.asarray(gain, dtype=float), (size,)).copy()
    except ValueError:
        raise ValueError(f"{name} must be a scalar or have shape ({size},)") from None
    if not np.all(np.isfinite(gain)) or np.any(gain < 0):
        raise ValueError(f"{name} must be finite and >= 0, got {gain}")
    return gain


class TrackingForce(Diagram):
    """The tracking force of the reproduction, a PD on the goal error (eq. 23).

    .. pydrake_system::

        name: TrackingForce
        input_ports:
        - x_star
        - xdot_star
        - x_goal
        output_ports:
        - F_tr

    F_tr = K_ptr (x_g - x*) + K_dtr xdot* (eq. 23), in N, from positions in m and
    velocities in m/s, from Drake's primitives in the order of the equation: the goal error
    ``Adder`` (x_g + (-x*), a ``Gain`` of -1), ``MatrixGain`` K_ptr and K_dtr (diagonal), and
    their ``Adder``. No state, direct feedthrough: it follows the rate of its inputs. Drake
    systems only, so it clones and converts to AutoDiffXd.

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
        Diagram.__init__(self)
        if not isinstance(size, (int, np.integer)) or size < 1:
            raise ValueError(f"size must be an integer >= 1, got {size!r}")
        K_p = np.diag(_check_gain(kp, "kp", size))
        K_d = np.diag(_check_gain(kd, "kd", size))
        builder = DiagramBuilder()
        negate = builder.AddNamedSystem("negate_x_star", Gain(-1.0, size))
        error = builder.AddNamedSystem("goal_error", Adder(2, size))
        stiffness = builder.AddNamedSystem("K_ptr", MatrixGain(K_p))
        damping = builder.AddNamedSystem("K_dtr", MatrixGain(K_d))
        total = builder.AddNamedSystem("F_tr", Adder(2, size))
        builder.Connect(negate.get_output_port(), error.get_input_port(1))
        builder.Connect(error.get_output_port(), stiffness.get_input_port())
        builder.Connect(stiffness.get_output_port(), total.get_input_port(0))
        builder.Connect(damping.get_output_port(), total.get_input_port(1))
        builder.ExportInput(negate.get_input_port(), "x_star")
        builder.ExportInput(damping.get_input_port(), "xdot_star")
        builder.ExportInput(error.get_input_port(0), "x_goal")
        builder.ExportOutput(total.get_output_port(), "F_tr")
        builder.BuildInto(self)
        self.set_name("TrackingForce")
