"""Who leads: the blend of the operator's command and the learnt policy, and the link watchdog."""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake.assist.config import ASSIST_MODES, AssistConfig


def target_weight(
    mode, *, weight, confidence, disagreement, scale, activation, low, high, delay=0.0,
    trust_delay=0.0, trust_weight=1.0,
):  # fmt: skip
    """The arbitration law's target weight w* in [0, 1] (docs/shared_control.md).

    - ``none``: 0; ``fixed``: W;
    - ``confidence``: W kappa exp(-(d / delta)^2);
    - ``emg``: W kappa exp(-(d / delta)^2) (1 - c), c = clip((a - a_lo) / (a_hi - a_lo), 0, 1);
    - ``confidence`` and ``emg`` with ``trust_delay`` T_t > 0: at least W_t min(1, T / T_t),
      T the one-way delay, W_t ``trust_weight``: under delay neither the disagreement nor
      the tension say the operator is right (the command is late and a person working a
      late loop tenses).

    Parameters
    ----------
    mode : one of ASSIST_MODES
    weight : float, W in [0, 1]
    confidence : float, kappa in [0, 1] (:class:`~hemg_drake.assist.intent.IntentModel`)
    disagreement : float, d (m), |operator's command - policy's point|
    scale : float, delta (m)
    activation : float, a, the EMG chain's muscle activation
    low, high : floats, a_lo < a_hi, the co-contraction band
    delay : float, T (s), the link's one-way delay
    trust_delay : float, T_t (s); 0: no floor
    trust_weight : float, W_t in [0, 1], the floor's largest value
    """
    if mode == "none":
        return 0.0
    if mode == "fixed":
        return float(weight)
    w = float(weight) * float(np.clip(confidence, 0.0, 1.0)) * np.exp(-((disagreement / scale) ** 2))
    if mode == "emg":
        w *= 1.0 - float(np.clip((activation - low) / (high - low), 0.0, 1.0))
    if trust_delay > 0.0:
        w = max(w, float(trust_weight) * min(1.0, float(delay) / float(trust_delay)))
    return float(w)


def newest_command_age(t, delay, gap_start, gap_end):
    """Age (s) at time t of the newest command that has arrived through a link of constant
    one-way ``delay`` (s) that loses what is sent in [gap_start, gap_end): t - s*, s* the
    newest sending time that is not lost, at most t - delay."""
    sent = t - delay
    if gap_start <= sent < gap_end:
        sent = gap_start
    return t - sent


@TemplateSystem.define("Arbitration_", T_list=[float, AutoDiffXd])
def Arbitration_(T):
    class Impl(LeafSystem_[T]):
        """The slave's reference: the operator's mapped command blended with the learnt policy.

        .. pydrake_system::

            name: Arbitration
            input_ports:
            - p_WE_command
            - x_policy
            - h_policy
            - confidence
            - activation
            - enabled
            output_ports:
            - p_WE_reference
            - weight
            - guidance_force
            - link_lost

        Policy blending (Dragan & Srinivasa 2013) arbitrated by the model's confidence and
        the operator's muscles (docs/shared_control.md):

            p_WE_reference = (1 - w) p_cmd + w x_pol,
            w_{k+1} = w_k + (T / tau_w) (w*_k - w_k),

        w* of :func:`target_weight` (``config.mode``), p_cmd the operator's command as the
        slave receives it (``p_WE_command``, 3, m, W), x_pol the policy's point
        (``x_policy``: the LQR tracker re-planned from the measured tool point, 3, m, W),
        kappa the intent estimator's ``confidence`` (1), a the EMG chain's ``activation``
        (1; read in mode ``emg`` only). ``enabled`` (1): the person's switch (the teleop
        page's A key, :class:`~hemg_drake.teleop.browser.BrowserMaster`'s ``assist_on``);
        below 0.5 the assist is off, w* = 0 as in mode ``none`` (the weight falls with its
        filter, no step), and the watchdog does not take over. ``guidance_force`` (3, N, W) = K_g w (x_pol - p_cmd),
        the pull toward the learnt path that the force feedback carries to the master.
        ``weight`` (1) is w, ``link_lost`` (1) 0 or 1.

        Link watchdog: the command in hand is the newest that arrived through a link of
        one-way delay ``delay`` (s) that loses what is sent in the numeric parameter's gap
        [gap_start, gap_end) (:func:`newest_command_age`); during the gap the last arrived
        command is held. When its age exceeds ``config.link_timeout`` the link is lost:
        w* = 1, and the policy runs alone until its most probable state (``h_policy``, N)
        leaves the one active at the loss, where the reference holds x_pol (the current
        phase completed, then hold). The link's return clears the watchdog. In mode
        ``none`` (built only to simulate a gap) nothing takes over: w stays 0 and the slave
        holds the last command, today's teleop on a lossy link.

        Updated every ``period`` (the master's); the reference is a direct feedthrough of
        the command (so w = 0 gives the command itself, bit for bit). State: [w, held
        command (3), phase at the loss (-1: none), holding (0/1), hold point (3)]. Numeric
        parameter [delay, gap_start, gap_end] (s). Clones (AutoDiffXd: built, not run).

        Parameters
        ----------
        config : AssistConfig
        period : float
            Update period (s).
        delay : float
            The master-to-slave one-way delay (s).
        p_WE_initial : 3 floats
            The command held before the first update (m, W).
        n_states : int
            N, the policy's number of states.
        """

        def _construct(self, *, config, period, delay, p_WE_initial, n_states, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._arguments = dict(
                config=config, period=period, delay=delay, p_WE_initial=p_WE_initial,
                n_states=n_states,
            )  # fmt: skip
            if not isinstance(config, AssistConfig) or config.mode not in ASSIST_MODES:
                raise ValueError(f"config must be an AssistConfig with mode in {ASSIST_MODES}")
            self._config = config
            self._period = float(period)
            self._rate = min(1.0, self._period / config.weight_time_constant)
            gap_end = config.gap_start + config.gap_duration
            self._link = self.DeclareNumericParameter(
                BasicVector_[T]([float(delay), config.gap_start, gap_end])
            )
            self._inputs = {
                "p_WE_command": self.DeclareVectorInputPort("p_WE_command", 3),
                "x_policy": self.DeclareVectorInputPort("x_policy", 3),
                "h_policy": self.DeclareVectorInputPort("h_policy", int(n_states)),
                "confidence": self.DeclareVectorInputPort("confidence", 1),
                "activation": self.DeclareVectorInputPort("activation", 1),
                "enabled": self.DeclareVectorInputPort("enabled", 1),
            }
            p0 = np.asarray(p_WE_initial, dtype=float).tolist()
            initial = [0.0, *p0, -1.0, 0.0, *p0]
            self._state = self.DeclareDiscreteState(np.array(initial))
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=self._period, offset_sec=0.0, update=self._update
            )
            self.DeclareVectorOutputPort("p_WE_reference", 3, self._calc_reference)
            self.DeclareVectorOutputPort(
                "weight", 1, self._calc_weight, prerequisites_of_calc={self.xd_ticket()}
            )
            self.DeclareVectorOutputPort("guidance_force", 3, self._calc_guidance)
            self.DeclareVectorOutputPort("link_lost", 1, self._calc_link_lost)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._arguments, converter=converter)

        def _read(self, context, name):
            return np.array(self._inputs[name].Eval(context), dtype=float)

        def _values(self, context):
            return np.array(context.get_discrete_state(self._state).CopyToVector(), dtype=float)

        def _link_values(self, context):
            return np.array(context.get_numeric_parameter(self._link).CopyToVector(), dtype=float)

        def _age(self, context):
            delay, start, end = self._link_values(context)
            return newest_command_age(context.get_time(), delay, start, end)

        def _command(self, context, state):
            """The command in hand: live, or the last arrived while the gap loses them."""
            delay, start, end = self._link_values(context)
            if start <= context.get_time() - delay < end:
                return state[1:4]
            return self._read(context, "p_WE_command")

        def _model_point(self, context, state):
            return state[6:9] if state[5] > 0.5 else self._read(context, "x_policy")

        def _update(self, context, discrete_state):
            state = self._values(context)
            config = self._config
            command = self._command(context, state)
            x_policy = self._read(context, "x_policy")
            lost = self._age(context) > config.link_timeout
            on = self._read(context, "enabled")[0] >= 0.5
            if not on:  # switched off by the person: today's teleop (the weight decays)
                target = 0.0
                state[4:6] = (-1.0, 0.0)
            elif lost and config.mode == "none":  # today's teleop: the stale command, alone
                target = 0.0
            elif lost:
                target = 1.0
                phase = int(np.argmax(self._read(context, "h_policy")))
                if state[4] < 0:
                    state[4] = phase
                elif state[5] < 0.5 and phase != int(state[4]):
                    state[5], state[6:9] = 1.0, x_policy
            else:
                state[4:6] = (-1.0, 0.0)
                activation = self._read(context, "activation")[0] if config.mode == "emg" else 0
                target = target_weight(
                    config.mode,
                    weight=config.weight,
                    confidence=self._read(context, "confidence")[0],
                    disagreement=float(np.linalg.norm(command - x_policy)),
                    scale=config.disagreement_scale,
                    activation=activation,
                    low=config.activation_low,
                    high=config.activation_high,
                    delay=self._link_values(context)[0],
                    trust_delay=config.trust_delay,
                    trust_weight=config.trust_weight,
                )
            state[0] += self._rate * (target - state[0])
            state[1:4] = command
            discrete_state.set_value(self._state, state)

        def _calc_reference(self, context, output):
            state = self._values(context)
            w = state[0]
            command = self._command(context, state)
            if w == 0.0 and state[5] < 0.5:
                output.SetFromVector(command)
                return
            output.SetFromVector((1.0 - w) * command + w * self._model_point(context, state))

        def _calc_weight(self, context, output):
            output.SetAtIndex(0, self._values(context)[0])

        def _calc_guidance(self, context, output):
            state = self._values(context)
            pull = self._model_point(context, state) - self._command(context, state)
            output.SetFromVector(self._config.guidance_stiffness * state[0] * pull)

        def _calc_link_lost(self, context, output):
            output.SetAtIndex(0, float(self._age(context) > self._config.link_timeout))

    return Impl


Arbitration = Arbitration_[None]
