"""Force feedback: what the slave feels (or how far it lags) sent back to the master's motors,
optionally after a transport delay and through a time-domain passivity controller."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from hemg_drake._validate import all_finite, as_scalar
from hemg_drake.teleop.mapping import WorkspaceMapping
from hemg_drake.teleop.master import TOUCH_X_PEAK_FORCE, saturate_norm

MODES = ("force", "position_error")
# "none": the force as computed; "tdpa": Hannaford & Ryu's time-domain passivity observer
# and controller at the master's port.
PASSIVITY = ("none", "tdpa")


def passivity_step(force, v_MS, energy, period):
    """One sample of the time-domain passivity observer and controller (Hannaford & Ryu
    2002, eqs. 11-13 for a one-port of impedance causality: velocity in, force out).

    The channel behind the master (delay, slave, scene) is seen as a one-port at the
    master's port: it absorbs the power -F . v_MS (F the force it puts on the stylus). The
    observer sums that energy, E(n) = E(n-1) - T F(n) . v_MS(n); the controller adds a
    damper -alpha v_MS, with the smallest alpha >= 0 that keeps E(n) >= 0, so the channel
    never gives the master more energy than it took.

    Parameters
    ----------
    force : 3 floats, N, the force the channel would put on the stylus.
    v_MS : 3 floats, m/s, the stylus velocity.
    energy : float, J, E(n - 1).
    period : float, s, the sample period T.

    Returns
    -------
    (force, alpha): the force to apply (3 floats) and the damping added (N s/m).
    """
    power = sum(f * v for f, v in zip(force, v_MS))
    speed2 = sum(v * v for v in v_MS)
    predicted = energy - period * power
    if predicted >= 0.0 or speed2 == 0.0:
        return list(force), 0.0
    alpha = -predicted / (period * speed2)
    return [f - alpha * v for f, v in zip(force, v_MS)], alpha


class ForceFeedback(LeafSystem):
    """The Touch X motor force that lets the operator feel the slave, saturated at its peak.

    .. pydrake_system::

        name: ForceFeedback
        input_ports:
        - f_WE (mode "force")
        - p_WE (mode "position_error")
        - v_WE (mode "position_error")
        - p_MS (mode "position_error")
        - v_MS (mode "position_error", or passivity "tdpa")
        output_ports:
        - motor_force

    Two modes, chosen by ``mode``; only that mode's input ports exist.

    - ``"force"`` (default): ``f_WE`` (3, N) is the force the environment exerts on the
      slave end-effector E, in W (a contact force, or the tracking force of eq. 23). The
      operator feels it rotated into M and scaled back by the workspace map,
      F_m = gain * R_WM^T f_WE / scale (see :class:`WorkspaceMapping`).
    - ``"position_error"``: the paper's master PD, F_m = K_pm e + K_dm edot (Table I:
      K_pm = K_dm = 50), with e = p_MSdes - p_MS the gap between the slave's position
      mapped into M and the stylus, edot the same for velocities. Inputs: ``p_WE`` (3, m) and
      ``v_WE`` (3, m/s) the slave end-effector in W, ``p_MS`` and ``v_MS`` the stylus in M.
      The stylus is pulled towards where the slave is, so a blocked slave is felt as a
      spring. Sampled with the 1 kHz master, K_dm * period / mass must stay below 2 (it is
      1.1 with Table I's 50 N s/m on the 45 g tip).

    ``motor_force`` (3, N, in M) is saturated in norm at ``peak_force`` (7.9 N, Touch X), as
    the device driver would. By default (``delay_steps`` = 0, ``passivity`` = "none") the
    output is a direct feedthrough of the inputs, without state; the HapticMaster samples
    it at its own rate. NaN inputs raise ValueError.

    Delay and passivity (``docs/studies.md``). ``delay_steps`` = n > 0 delays the slave's
    side of the inputs (``f_WE``, or ``p_WE`` and ``v_WE``) by n samples of ``period``: the
    slave-to-master half of the teleoperation channel (the workspace map delays the
    master-to-slave half). The output at sample k uses the slave's values of sample k - n
    (before the start: the values at the start, the slave at rest) and the master's of
    sample k. ``passivity`` = "tdpa" adds the time-domain passivity observer and controller
    of Hannaford & Ryu (2002) at the master's port (:func:`passivity_step`, the energy in a
    discrete state; in mode "force" it needs the ``v_MS`` input), applied after the
    saturation, whose result is saturated again; the observer sums the force actually
    applied. With either option the system holds discrete state updated every ``period``
    (at t = 0, k ``period``), filled with the inputs at initialisation.

    Parameters
    ----------
    mapping : WorkspaceMapping
    mode : {"force", "position_error"}
    gain : float
        Extra force scale in mode "force" (dimensionless, >= 0).
    stiffness, damping : float
        K_pm (N/m) and K_dm (N s/m) in mode "position_error".
    peak_force : float
        Saturation of the output's norm (N).
    delay_steps : int
        Slave-to-master transport delay in samples of ``period`` (>= 0).
    passivity : {"none", "tdpa"}
    period : float
        Sample period of the delay and the passivity controller (s): the haptic loop's.
    """

    def __init__(
        self,
        *,
        mapping,
        mode="force",
        gain=1.0,
        stiffness=50.0,
        damping=50.0,
        peak_force=TOUCH_X_PEAK_FORCE,
        delay_steps=0,
        passivity="none",
        period=1e-3,
    ):
        LeafSystem.__init__(self)
        if not isinstance(mapping, WorkspaceMapping):
            raise ValueError(f"mapping must be a WorkspaceMapping, got {type(mapping).__name__}")
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        self.mapping = mapping
        self.mode = mode
        self.gain = as_scalar("gain", gain, strict=False)
        self.stiffness = as_scalar("stiffness", stiffness, strict=False)
        self.damping = as_scalar("damping", damping, strict=False)
        self.peak_force = as_scalar("peak_force", peak_force, strict=False)
        if isinstance(delay_steps, bool) or int(delay_steps) != delay_steps or delay_steps < 0:
            raise ValueError(f"delay_steps must be a non-negative integer, got {delay_steps!r}")
        if passivity not in PASSIVITY:
            raise ValueError(f"passivity must be one of {PASSIVITY}, got {passivity!r}")
        self.delay_steps = int(delay_steps)
        self.passivity = passivity
        self.period = as_scalar("period", period)
        if self.period <= 0:
            raise ValueError(f"period must be positive, got {period!r}")
        self._slave_names = ("f_WE",) if mode == "force" else ("p_WE", "v_WE")
        names = ("f_WE",) if mode == "force" else ("p_WE", "v_WE", "p_MS", "v_MS")
        if passivity != "none" and "v_MS" not in names:
            names += ("v_MS",)
        self._inputs = {name: self.DeclareVectorInputPort(name, 3) for name in names}
        self.stateful = self.delay_steps > 0 or passivity != "none"
        prerequisites = {self.all_input_ports_ticket()}
        if self.stateful:
            width = 3 * len(self._slave_names)
            # [slave samples k - n .. k - 1 (oldest first), E]: E the observer's energy (J).
            self._state = self.DeclareDiscreteState(width * self.delay_steps + 1)
            self.DeclareInitializationDiscreteUpdateEvent(self._initialize)
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=self.period, offset_sec=0.0, update=self._update
            )
            prerequisites.add(self.xd_ticket())
        self._motor_force_output = self.DeclareVectorOutputPort(
            "motor_force",
            3,
            self._calc_motor_force,
            prerequisites_of_calc=prerequisites,
        )

    def _input(self, context, name):
        value = self._inputs[name].Eval(context)
        if not all_finite(value.tolist()):
            raise ValueError(f"{name} must be finite, got {value.tolist()}")
        return value

    def _slave_sample(self, context):
        """The slave's side of the inputs now: f_WE, or [p_WE, v_WE]."""
        if len(self._slave_names) == 1:  # force mode, at 1 kHz: no copy
            return self._input(context, self._slave_names[0])
        return np.concatenate([self._input(context, name) for name in self._slave_names])

    def _force(self, context, slave):
        """The saturated force from the slave's values ``slave`` and the master's now."""
        if self.mode == "force":
            force = self.mapping.force_to_master_floats(slave.tolist(), self.gain)
        else:
            error = self.mapping.slave_to_master(slave[:3]) - self._input(context, "p_MS")
            error_rate = self.mapping.velocity_to_master(slave[3:]) - self._input(
                context, "v_MS"
            )
            force = (self.stiffness * error + self.damping * error_rate).tolist()
        return saturate_norm(force, self.peak_force)

    def _stateful_force(self, context):
        """(force, v_MS, E) at this sample, from the delayed slave values and the energy."""
        state = context.get_discrete_state(self._state).value()
        width = 3 * len(self._slave_names)
        slave = state[:width] if self.delay_steps else self._slave_sample(context)
        force = self._force(context, slave)
        energy = float(state[-1])
        if self.passivity == "none":
            return force, None, energy
        if not self._inputs["v_MS"].HasValue(context):
            raise ValueError(
                "passivity 'tdpa' needs the stylus velocity: connect the master's v_MS to "
                "the force feedback's v_MS input"
            )
        v_MS = self._input(context, "v_MS").tolist()
        force, _ = passivity_step(force, v_MS, energy, self.period)
        return saturate_norm(force, self.peak_force), v_MS, energy

    def _initialize(self, context, discrete_state):
        # Before the start the slave was at rest where it starts: the delay holds that.
        samples = np.tile(self._slave_sample(context), self.delay_steps)
        discrete_state.set_value(self._state, np.append(samples, 0.0))

    def _update(self, context, discrete_state):
        force, v_MS, energy = self._stateful_force(context)
        if v_MS is not None:
            energy -= self.period * sum(f * v for f, v in zip(force, v_MS))
        state = context.get_discrete_state(self._state).value()
        width = 3 * len(self._slave_names)
        samples = state[:-1]
        if self.delay_steps:
            samples = np.concatenate([samples[width:], self._slave_sample(context)])
        discrete_state.set_value(self._state, np.append(samples, energy))

    def energy(self, context):
        """The passivity observer's energy E (J): what the channel took from the master."""
        if not self.stateful:
            raise ValueError("energy needs delay_steps > 0 or passivity 'tdpa' (a state)")
        return float(context.get_discrete_state(self._state).value()[-1])

    def _calc_motor_force(self, context, output):
        if self.stateful:
            output.SetFromVector(self._stateful_force(context)[0])
            return
        output.SetFromVector(self._force(context, self._slave_sample(context)))
