"""The operator's intent, online: the HSMM's forward variable observing the commanded motion."""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake.learning.forward import ResidualForward
from hemg_drake.learning.gmr import gaussian_log_pdf
from hemg_drake.learning.gmr_policy import check_position


class IntentModel:
    """What the estimator needs of a fitted HSMM, and its step (plain numpy, no Drake).

    The step is the residual-duration forward recursion of
    :class:`~hemg_drake.learning.forward.ResidualForward` (eq. 12 online; the one
    implementation), with the emission of the commanded position x_t under each state's
    position marginal, log N(x_t | mu_i^x, S_i^xx) (GMR's input likelihood). Beside it the
    estimator keeps the *normalised likelihood* of the motion: per step

        r_t = log sum_i q_i N(x_t | mu_i^x, S_i^xx) - sum_i q_i l_i,
        l_i = log N(mu_i^x | mu_i^x, S_i^xx) - P / 2,

    q the predicted state probabilities before x_t, l_i the expected log-density of a sample
    of state i (the chi-square's mean P below the peak), so r_t is about 0 for motion the
    model expects and falls by d^2 / 2 for a sample d sigma away; an exponential average
    rbar_t = rbar_{t-1} + beta (r_t - rbar_{t-1}), beta = dt / tau. The confidence is

        kappa_t = (1 - H(h_t) / log N) exp(min(0, rbar_t) / P) in [0, 1],

    the belief's certainty (one minus its normalised entropy; 1 for N = 1) times the fit of
    the recent motion.

    Parameters
    ----------
    model : HSMM
        Fitted (P position dimensions).
    dt : float
        Step (s), the model's sample period.
    likelihood_time_constant : float
        tau of the average (s), >= dt.
    command_noise : float
        sigma_c (m), >= 0.
    """

    def __init__(self, model, dt, likelihood_time_constant, command_noise=0.0):
        self.forward = ResidualForward(model)
        self.n_states = model.n_states
        dims = model.position_dims_
        self.n_position = len(dims)
        self.position_means = model.means_[:, dims].copy()
        block = model.covariances_[np.ix_(range(self.n_states), dims, dims)]
        self.covariances = block + float(command_noise) ** 2 * np.eye(self.n_position)
        peaks = gaussian_log_pdf(self.position_means, self.position_means, self.covariances)
        self.reference = np.diag(peaks) - 0.5 * self.n_position
        transmat = model.transmat_.copy()
        final = transmat.sum(axis=1) == 0
        transmat[final, final] = 1.0
        self.transmat = transmat
        self.beta = min(1.0, float(dt) / float(likelihood_time_constant))

    def check_position(self, x, name="p_WE_command"):
        return check_position(x, self.n_position, name)

    def initial(self):
        """(predicted forward variable, h, rbar) before the first observation."""
        predicted = self.forward.initial()
        return predicted, predicted.sum(axis=1), 0.0

    def step(self, predicted, rbar, x):
        """One observation x: (h, predicted_next, rbar_next)."""
        log_emission = gaussian_log_pdf(x[None], self.position_means, self.covariances)[0]
        q = predicted.sum(axis=1)
        q = q / q.sum()
        top = log_emission.max()
        evidence = top + np.log(max(float(q @ np.exp(log_emission - top)), 1e-300))
        r = evidence - float(q @ self.reference)
        h, predicted_next = self.forward.step(predicted, log_emission)
        return h, predicted_next, rbar + self.beta * (r - rbar)

    def confidence(self, h, rbar):
        """kappa of the belief h and the averaged normalised likelihood rbar."""
        if self.n_states == 1:
            certainty = 1.0
        else:
            p = np.clip(h, 1e-300, None)
            entropy = -float(np.sum(h * np.log(p)))
            certainty = max(0.0, 1.0 - entropy / np.log(self.n_states))
        return certainty * float(np.exp(min(0.0, rbar) / self.n_position))

    def next_target(self, h):
        """Position mean of the most probable state entered at the next transition."""
        return self.position_means[int(np.argmax(h @ self.transmat))]


@TemplateSystem.define("IntentEstimator_", T_list=[float, AutoDiffXd])
def IntentEstimator_(T):
    class Impl(LeafSystem_[T]):
        """The task's phase, the next target and the model's confidence, from the commands.

        .. pydrake_system::

            name: IntentEstimator
            input_ports:
            - p_WE_command
            output_ports:
            - h
            - phase
            - next_target
            - confidence

        Every ``dt`` (the model's sample period) the system reads the operator's commanded
        tool point ``p_WE_command`` (3, m, in W: the workspace map's output as the slave
        receives it) and takes one step of the HSMM's forward variable (eq. 12, the
        residual-duration recursion of :class:`~hemg_drake.learning.forward.ResidualForward`)
        and of the averaged normalised likelihood (:class:`IntentModel`). Outputs, all
        from the discrete state (no direct feedthrough): ``h`` (N) the state probabilities,
        ``phase`` (1) the most probable state's index, ``next_target`` (3, m) the position
        mean of the state most probably entered next, ``confidence`` (1) kappa in [0, 1].
        The discrete state holds the predicted forward variable (N x d_max), h and rbar;
        the model is immutable. Clones (an AutoDiffXd instantiation exists; its update
        runs on floats and is not differentiable).

        Parameters
        ----------
        model : HSMM
            Fitted.
        dt : float
            Update period (s), the model's sample period (the scenario's log period).
        likelihood_time_constant : float
            tau of the likelihood's average (s).
        command_noise : float
            sigma_c, the command's spread about the learnt positions (m).
        """

        def _construct(
            self, *, model, dt, likelihood_time_constant=0.2, command_noise=0.0, converter=None
        ):
            LeafSystem_[T].__init__(self, converter)
            self._arguments = dict(
                model=model, dt=dt, likelihood_time_constant=likelihood_time_constant,
                command_noise=command_noise,
            )  # fmt: skip
            if not (np.isfinite(dt) and dt > 0):
                raise ValueError(f"dt must be a finite number > 0 (s), got {dt!r}")
            self.intent = IntentModel(model, dt, likelihood_time_constant, command_noise)
            predicted, h, rbar = self.intent.initial()
            self._shape = predicted.shape
            self._input = self.DeclareVectorInputPort("p_WE_command", self.intent.n_position)
            self._predicted_state = self.DeclareDiscreteState(predicted.ravel())
            self._h_state = self.DeclareDiscreteState(h)
            self._rbar_state = self.DeclareDiscreteState([rbar])
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=dt, offset_sec=0.0, update=self._update
            )
            self.DeclareStateOutputPort("h", self._h_state)
            state = {self.xd_ticket()}
            self.DeclareVectorOutputPort("phase", 1, self._calc_phase, state)
            self.DeclareVectorOutputPort(
                "next_target", self.intent.n_position, self._calc_next_target, state
            )
            self.DeclareVectorOutputPort("confidence", 1, self._calc_confidence, state)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._arguments, converter=converter)

        def _values(self, context, index):
            return np.array(context.get_discrete_state(index).CopyToVector(), dtype=float)

        def _update(self, context, discrete_state):
            x = self.intent.check_position(self._input.Eval(context))
            predicted = self._values(context, self._predicted_state).reshape(self._shape)
            rbar = self._values(context, self._rbar_state)[0]
            h, predicted_next, rbar_next = self.intent.step(predicted, rbar, x)
            discrete_state.set_value(self._predicted_state, predicted_next.ravel())
            discrete_state.set_value(self._h_state, h)
            discrete_state.set_value(self._rbar_state, [rbar_next])

        def _calc_phase(self, context, output):
            output.SetAtIndex(0, float(np.argmax(self._values(context, self._h_state))))

        def _calc_next_target(self, context, output):
            output.SetFromVector(self.intent.next_target(self._values(context, self._h_state)))

        def _calc_confidence(self, context, output):
            h = self._values(context, self._h_state)
            rbar = self._values(context, self._rbar_state)[0]
            output.SetAtIndex(0, self.intent.confidence(h, rbar))

    return Impl


IntentEstimator = IntentEstimator_[None]
