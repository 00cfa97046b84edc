"""Settings of the teleoperation systems: workspace map, haptic master, simulated operator,
force feedback (eqs. 19-21). Each dataclass owns its defaults; its system takes one.
"""

import dataclasses as dc

from hemg_drake.config_fields import checked, key_path

# Force-feedback modes and passivity layers (teleop/feedback.py).
FEEDBACK_MODES = ("force", "position_error")
FEEDBACK_PASSIVITY = ("none", "tdpa")
# Longest transport delay each way, in master samples: 10 s at the 1 kHz servo rate. The
# delay line holds that many samples (16 numbers each way) and shifts them every sample: a
# demonstration with 10 000 samples each way simulates about 2x slower than without delay,
# 5.6x at 100 000 (measured; 1e9 asked 48 GB and failed).
MAX_DELAY_STEPS = 10_000
DELAY_BOUND = "10 s of the master's 1 ms samples"


@dc.dataclass
class MappingConfig:
    """Master-to-slave workspace map (:class:`~hemg_drake.teleop.mapping.WorkspaceMapping`)."""

    # Slave metres per master metre.
    scale: float = checked(1.0, positive=True)
    # The slave point that the centre of the master's workspace maps to, from the scene
    # frame's origin, in the scene frame T (m): the map follows the scene.
    scene_offset: list[float] = checked([0.0, 0.0, 0.0], signed=True, size=3)
    # Orientation of the master frame M relative to the scene frame T, roll-pitch-yaw in
    # degrees (R_WM = R_WT R_TM). The default puts the operator behind the robot, facing
    # the way it faces.
    rpy_deg: list[float] = checked([90.0, 0.0, -90.0], signed=True, size=3)
    # Constant transport delay of the teleoperation channel, in master samples (1 ms each).
    delay_steps: int = checked(0, maximum=MAX_DELAY_STEPS, why=DELAY_BOUND)


@dc.dataclass
class MasterConfig:
    """Touch X tip dynamics (:class:`~hemg_drake.teleop.master.HapticMaster`), SI units."""

    # Apparent mass at the tip (kg).
    mass: float = checked(0.045, positive=True)
    # Viscous backdrive damping (N s/m).
    damping: float = checked(0.1)
    # Coulomb backdrive friction (N).
    friction: float = checked(0.0)
    # Motor force saturation (N), the Touch X peak force.
    peak_force: float = checked(7.9)
    # Workspace box, width x height x depth (m).
    workspace_size: list[float] = checked([0.16, 0.12, 0.12], positive=True, size=3
    )
    # Soft walls beyond the box: spring (N/m) and damper (N s/m).
    wall_stiffness: float = checked(5000.0)
    wall_damping: float = checked(20.0)
    # Sample period of the haptic loop (s): the device's servo rate, 1 kHz.
    period: float = checked(1e-3, positive=True)


OPERATOR_STYLES = ("scripted", "human")


@dc.dataclass
class HumanStyleConfig:
    """The human-like operator's timing (``operator.style: human``;
    :mod:`~hemg_drake.teleop.human_style`): every figure a range that a seeded uniform draw
    picks from, per take or per segment."""

    # Speed factor of each segment (1: the plan's own pace): the take's tempo, log-uniform in
    # this range, times the phase's own, log-uniform in [1 / phase_spread, phase_spread],
    # clipped to the range.
    tempo_range: list[float] = checked([0.5, 2.0], positive=True, size=2)
    phase_spread: float = checked(1.5, positive=True)
    # Idle lead-in before the plan starts (s), uniform in the range.
    idle_range: list[float] = checked([0.3, 2.0], size=2)
    # A pause at each inner waypoint with this probability, lasting (s) uniform in the range.
    pause_probability: float = checked(0.3, fraction=True)
    pause_range: list[float] = checked([0.2, 1.0], size=2)
    # A free move in the air overshoots its end with this probability, by a fraction of its
    # displacement uniform in the range, at most max_overshoot (m), then comes back in
    # correction_time (s).
    overshoot_probability: float = checked(0.5, fraction=True)
    overshoot_range: list[float] = checked([0.1, 0.3], size=2)
    max_overshoot: float = checked(0.01)
    correction_time: float = checked(0.3, positive=True)

    def check(self, key=""):
        """Each range [low, high] with low <= high (ValueError naming the key)."""
        for name in ("tempo_range", "idle_range", "pause_range", "overshoot_range"):
            low, high = getattr(self, name)
            if low > high:
                raise ValueError(
                    f"key '{key_path(key, name)}' must be [low, high] with low <= high, "
                    f"got {[low, high]}"
                )
        if self.phase_spread < 1:
            raise ValueError(
                f"key '{key_path(key, 'phase_spread')}' must be >= 1, got {self.phase_spread}"
            )


@dc.dataclass
class VisualConfig:
    """An operator who acts on what it sees (``operator.visual``;
    :mod:`~hemg_drake.teleop.visual`): it sees the slave's tool through the channel's
    slave-to-master delay plus its own reaction time, moves on to the plan's next segment
    only when it sees the previous one reached and settled (move and wait, Ferrell 1965),
    corrects toward the error it sees with an integral gain (the crossover model's
    operator: the loop L(s) = w_c e^{-s tau} / s, McRuer & Jex 1967), gives up and lets go
    when a waypoint is not reached within its patience, and trembles at 8-12 Hz."""

    enabled: bool = False
    # Visuomotor reaction time (s): ~0.2 s for a visual stimulus (e.g. Welford 1980), on top
    # of the channel's slave-to-master delay.
    reaction_time: float = checked(0.2)
    # Crossover frequency w_c (rad/s) of the visual correction, the gain of the integral of
    # the seen error: 4 rad/s, the human's crossover on a position task with ~0.2 s
    # effective delay (phase margin about 45 deg without the channel's delay); the operator
    # does not lower it for the channel's delay (a first session).
    gain: float = checked(4.0)
    # The smallest error the operator sees (m, in M): errors below it are not corrected,
    # and a waypoint counts as reached within it.
    tolerance: float = checked(0.003, positive=True)
    # A waypoint counts as reached when seen within the tolerance for this long (s).
    dwell: float = checked(0.2)
    # Bound of the correction's norm (m, in M): how far beyond its plan the hand reaches.
    max_correction: float = checked(0.03)
    # Seconds held at a waypoint not seen reached before the operator lets go for good.
    patience: float = checked(3.0, positive=True)
    # Tremor: a sinusoid on the hand's target, amplitude (m) per axis, frequency (Hz)
    # uniform in the range, phase per axis uniform (physiological tremor 8-12 Hz).
    tremor_amplitude: float = checked(0.0)
    tremor_frequency: list[float] = checked([8.0, 12.0], positive=True, size=2)
    # Efference copy: the seen tool is compared with the command the operator sent when
    # that image's motion began (plan clock and correction, delayed by the whole loop:
    # command delay, video delay, reaction), and the corrections sent since count as under
    # way (a Smith predictor, as the cerebellum is modelled: Miall et al. 1993). So a move
    # seen late is no error and the correction loop has no delay to oscillate with. Off,
    # the lag seen during a long fast move is integrated as error and the correction winds
    # up, and beyond w_c (tau + 2T) = pi/2 it oscillates (the pin study ran with it off).
    efference_copy: bool = False

    def check(self, key=""):
        low, high = self.tremor_frequency
        if low > high:
            raise ValueError(
                f"key '{key_path(key, 'tremor_frequency')}' must be [low, high] with "
                f"low <= high, got {[low, high]}"
            )


@dc.dataclass
class OperatorConfig:
    """The simulated operator (:class:`~hemg_drake.teleop.operator.SimulatedOperator`) and
    its seeded variability between demonstrations."""

    # Hand impedance pushing the stylus toward the planned point, in the master frame:
    # stiffness (N/m), damping (N s/m), and the saturation of the hand force's norm (N).
    hand_stiffness: float = checked(300.0, positive=True)
    hand_damping: float = checked(5.0)
    max_hand_force: float = checked(15.0)
    # Muscle activation in [0, 1]: relaxed, moving freely, working against the task (at
    # effort 1).
    rest_activation: float = checked(0.05, fraction=True)
    free_activation: float = checked(0.2, fraction=True)
    forceful_activation: float = checked(0.7, fraction=True
    )
    # Co-contraction: activation added per newton of force felt on the stylus (1/N).
    co_contraction_gain: float = checked(0.05)
    # Time constant of the muscle activation (s).
    activation_time_constant: float = checked(0.04, positive=True
    )
    # Sample period of the activation (s): the MYO's 1/200 s, the rate at which the sEMG
    # source reads it.
    period: float = checked(0.005, positive=True)
    # Variability (TaskPlan.perturbed): log-normal spread of each segment's duration, the
    # path offset's standard deviation per world axis (m), log-normal spread of the effort.
    timing_std: float = checked(0.1)
    path_std: list[float] = checked([0.003, 0.003, 0.003], size=3)
    effort_std: float = checked(0.1)
    # "scripted": the plan's pace with the variability above; "human": also the human-like
    # timing of `human` (per-phase tempo, pauses, overshoot then correction, idle start).
    style: str = checked("scripted", choices=OPERATOR_STYLES)
    human: HumanStyleConfig = dc.field(default_factory=HumanStyleConfig)
    # An operator who acts on what it sees (off: the plan in time, whatever it sees).
    visual: VisualConfig = dc.field(default_factory=VisualConfig)

    def model_parameters(self):
        """Keyword arguments of ``SimulatedOperator`` (all fields but the variability)."""
        data = dc.asdict(self)
        for name in ("timing_std", "path_std", "effort_std", "style", "human", "visual"):
            del data[name]
        return data


@dc.dataclass
class FeedbackConfig:
    """Force fed back to the master (:class:`~hemg_drake.teleop.feedback.ForceFeedback`)."""

    # "force": the slave's interaction force; "position_error": the master PD of Table I.
    mode: str = checked("force", choices=FEEDBACK_MODES)
    # Extra scale on the force in mode "force" (dimensionless).
    gain: float = checked(1.0)
    # K_pm (N/m) and K_dm (N s/m) in mode "position_error" (Table I: 50 and 50).
    stiffness: float = checked(50.0)
    damping: float = checked(50.0)
    # Saturation of the motor force (N).
    peak_force: float = checked(7.9)
    # Slave-to-master transport delay of the fed-back force (or of the slave's position in
    # mode "position_error"), in master samples (1 ms each); mapping.delay_steps is the
    # master-to-slave half.
    delay_steps: int = checked(0, maximum=MAX_DELAY_STEPS, why=DELAY_BOUND)
    # "none", or "tdpa": a time-domain passivity observer and controller at the master's
    # port (Hannaford & Ryu 2002) keeps the channel from giving the master more energy
    # than it took. Mode "force" needs the master's v_MS connected to it.
    passivity: str = checked("none", choices=FEEDBACK_PASSIVITY)
