"""Settings of the shared control (``assist:`` section of a scenario; docs/shared_control.md).

The default, ``mode: none``, builds no assist at all: the demonstration diagram is today's
teleoperation, bit for bit.
"""

import dataclasses as dc

from hemg_drake.config_fields import checked, key_path

# none: today's teleoperation; fixed: a constant weight; confidence: the weight follows the
# model's confidence and the disagreement; emg: that, lowered by the operator's
# co-contraction (docs/shared_control.md, the arbitration law).
ASSIST_MODES = ("none", "fixed", "confidence", "emg")


@dc.dataclass
class AssistConfig:
    """The intent estimator, the arbitration, the guidance force and the link watchdog
    (:mod:`hemg_drake.assist`)."""

    mode: str = checked("none", choices=ASSIST_MODES)
    # The fitted model (``model.npz`` written by ``hemg-drake learn``), read when mode is
    # not none. A relative path is taken from the working directory.
    model: str = ""
    # Weight of mode "fixed", and the largest weight of modes "confidence" and "emg" (the
    # delay-aware floor, trust_weight, may exceed it).
    weight: float = checked(0.5, fraction=True)
    # Disagreement scale delta (m): the weight is multiplied by exp(-(d / delta)^2), d the
    # distance between the operator's command and the policy's point.
    disagreement_scale: float = checked(0.02, positive=True)
    # Delay-aware trust T_t (s; 0: off): modes confidence and emg keep a weight of at least
    # W_t min(1, T / T_t), T the link's one-way delay, W_t = trust_weight
    # (docs/shared_control.md).
    trust_delay: float = checked(0.0)
    trust_weight: float = checked(1.0, fraction=True)
    # Co-contraction band of the EMG chain's activation (dimensionless): below ``low`` the
    # operator lets the model lead, above ``high`` the model gives way entirely.
    activation_low: float = checked(0.2, fraction=True)
    activation_high: float = checked(0.6, fraction=True)
    # Time constant of the weight's first-order filter (s): no step in the reference.
    weight_time_constant: float = checked(0.1, positive=True)
    # The operator's command about the learnt (tool) positions: a standard deviation (m)
    # added to each state's position spread in the estimator's likelihood.
    command_noise: float = checked(0.005)
    # Time constant of the estimator's average of the motion's likelihood (s).
    likelihood_time_constant: float = checked(0.2, positive=True)
    # Guidance on the master: a force K_g w (x_policy - p_command) at the slave, fed back
    # with the contact force (N/m; 0: none). Needs feedback.mode force and passivity tdpa.
    guidance_stiffness: float = checked(0.0)
    # Link watchdog: the newest command older than this (s) is a lost link; the model then
    # completes the current phase alone and holds.
    link_timeout: float = checked(1.0, positive=True)
    # A simulated outage of the master-to-slave link: commands sent in
    # [gap_start, gap_start + gap_duration) are lost (s; duration 0: none). With mode none
    # the link is simulated too (it needs the model): the slave holds the last command.
    gap_start: float = checked(0.0)
    gap_duration: float = checked(0.0)

    def check(self, key=""):
        """The co-contraction band's order (ValueError naming the key)."""
        if self.activation_high <= self.activation_low:
            raise ValueError(
                f"key '{key_path(key, 'activation_high')}' = {self.activation_high} must "
                f"exceed '{key_path(key, 'activation_low')}' = {self.activation_low}"
            )
