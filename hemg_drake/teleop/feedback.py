"""Force feedback: what the slave feels (or how far it lags) sent back to the master's motors,
optionally after a transport delay and through a time-domain passivity controller."""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import BasicVector_, Context_, Diagram, DiagramBuilder, LeafSystem_
from pydrake.systems.primitives import ConstantVectorSource, DiscreteTimeDelay, Multiplexer
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake._validate import all_finite, as_scalar
from hemg_drake.teleop.config import FEEDBACK_MODES, FEEDBACK_PASSIVITY, FeedbackConfig
from hemg_drake.teleop.mapping import WorkspaceMapping
from hemg_drake.teleop.master import saturate_norm

# Resolved once: a template lookup per call would cost microseconds at 1 kHz.
_DOUBLE_CONTEXT = Context_[float]


def passivity_step(force, v_MS, energy, period):
    """One sample of the time-domain passivity observer and controller (Hannaford & Ryu
    2002, eqs. 11-13 for a one-port of impedance causality: velocity in, force out).

    The channel behind the master (delay, slave, scene) is seen as a one-port at the
    master's port: it absorbs the power -F . v_MS (F the force it puts on the stylus). The
    observer sums that energy, E(n) = E(n-1) - T F(n) . v_MS(n); the controller adds a
    damper -alpha v_MS, with the smallest alpha >= 0 that keeps E(n) >= 0, so the channel
    never gives the master more energy than it took. Scalar-type agnostic (floats or
    AutoDiffXd; the switch is piecewise).

    Parameters
    ----------
    force : 3 scalars, N, the force the channel would put on the stylus.
    v_MS : 3 scalars, m/s, the stylus velocity.
    energy : scalar, J, E(n - 1).
    period : float, s, the sample period T.

    Returns
    -------
    (force, alpha): the force to apply (3 scalars) and the damping added (N s/m).
    """
    power = sum(f * v for f, v in zip(force, v_MS))
    speed2 = sum(v * v for v in v_MS)
    predicted = energy - period * power
    if predicted >= 0.0 or speed2 == 0.0:
        return list(force), 0.0
    alpha = -predicted / (period * speed2)
    return [f - alpha * v for f, v in zip(force, v_MS)], alpha


def _vector(port, context, name):
    """An input as a list of scalars; for double, checked finite (ValueError naming it)."""
    values = port.Eval(context).tolist()
    if isinstance(context, _DOUBLE_CONTEXT) and not all_finite(values):
        raise ValueError(f"{name} must be finite, got {values}")
    return values


@TemplateSystem.define("FeedbackLaw_", T_list=[float, AutoDiffXd])
def FeedbackLaw_(T):
    class Impl(LeafSystem_[T]):
        """The force-feedback law inside :class:`ForceFeedback` (see there for the maths).

        .. pydrake_system::

            name: FeedbackLaw
            input_ports:
            - f_WE (mode "force")
            - p_WE (mode "position_error")
            - v_WE (mode "position_error")
            - p_MS (mode "position_error")
            - v_MS (mode "position_error", or passivity "tdpa")
            - delayed (delay_steps > 0)
            output_ports:
            - motor_force

        ``delayed`` is [slave sample; valid] from Drake's ``DiscreteTimeDelay``: before the
        channel has carried a sample (valid = 0) the law uses the slave's values at
        initialisation, held in the discrete state [rest; E] with the passivity
        observer's energy E (J), updated every ``period`` when the passivity controller is
        on. The gains and the limit are a numeric parameter, [gain, K_pm, K_dm, peak_force]
        (dimensionless, N/m, N s/m, N), so one built diagram can run several. Inputs in SI
        units, frames as :class:`ForceFeedback`. Double and AutoDiffXd.
        """

        def _construct(self, *, mapping, period, config, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._mapping, self._config = mapping, config
            self._mode, self._passivity = config.mode, config.passivity
            # Gains and limit in the Context: [gain, K_pm (N/m), K_dm (N s/m), peak (N)].
            gains = [
                as_scalar(name, getattr(config, name), strict=False)
                for name in ("gain", "stiffness", "damping", "peak_force")
            ]
            self._gains_index = self.DeclareNumericParameter(BasicVector_[T](gains))
            self._period = as_scalar("period", period)
            self._delay_steps = int(config.delay_steps)
            R = mapping.R_WM.matrix()
            self._RT_rows = R.T.tolist()
            self._inverse_scale = 1.0 / mapping.scale
            self._scale = mapping.scale
            self._p_WMo = mapping.p_WMo.tolist()
            self._slave_names = ("f_WE",) if self._mode == "force" else ("p_WE", "v_WE")
            names = self._slave_names + (("p_MS", "v_MS") if self._mode != "force" else ())
            if self._passivity != "none" and "v_MS" not in names:
                names += ("v_MS",)
            self._inputs = {name: self.DeclareVectorInputPort(name, 3) for name in names}
            width = 3 * len(self._slave_names)
            self._width = width
            self.stateful = self._delay_steps > 0 or self._passivity != "none"
            prerequisites = {self.all_input_ports_ticket(), self.all_parameters_ticket()}
            if self._delay_steps > 0:
                self._delayed = self.DeclareVectorInputPort("delayed", width + 1)
            if self.stateful:
                # [the slave's sample at initialisation (width), E (J)].
                self._state = self.DeclareDiscreteState(width + 1)
                self.DeclareInitializationDiscreteUpdateEvent(self._initialize)
                if self._passivity != "none":
                    self.DeclarePeriodicDiscreteUpdateEvent(
                        period_sec=self._period, offset_sec=0.0, update=self._update
                    )
                prerequisites.add(self.xd_ticket())
            self.DeclareVectorOutputPort(
                "motor_force", 3, self._calc_motor_force, prerequisites_of_calc=prerequisites
            )
            if self.stateful:  # the passivity observer's E (J), for the logs
                self.DeclareVectorOutputPort(
                    "energy", 1, self._calc_energy, prerequisites_of_calc={self.xd_ticket()}
                )

        def _construct_copy(self, other, converter=None):
            Impl._construct(
                self, mapping=other._mapping, period=other._period, config=other._config,
                converter=converter,
            )  # fmt: skip

        def _live_sample(self, context):
            """The slave's side of the inputs now: f_WE, or [p_WE, v_WE] (a list)."""
            values = []
            for name in self._slave_names:
                values += _vector(self._inputs[name], context, name)
            return values

        def _state_values(self, context):
            group = context.get_discrete_state(self._state)
            if isinstance(context, _DOUBLE_CONTEXT):
                return group.value().tolist()
            return group.CopyToVector().tolist()

        def _slave_sample(self, context):
            """The slave's values this sample reads: delayed, or live."""
            if self._delay_steps == 0:
                return self._live_sample(context)
            delayed = _vector(self._delayed, context, "the delayed slave sample")
            if delayed[-1] > 0.5:
                return delayed[:-1]
            return self._state_values(context)[:-1]  # before the first sample: the slave at rest

        def gains(self, context):
            """[gain, K_pm, K_dm, peak_force] of ``context`` (its numeric parameter)."""
            group = context.get_numeric_parameter(self._gains_index)
            if isinstance(context, _DOUBLE_CONTEXT):
                return group.value().tolist()
            return group.CopyToVector().tolist()

        def _force(self, context, slave):
            """The saturated force from the slave's values and the master's now."""
            gain, stiffness, damping, peak_force = self.gains(context)
            if self._mode == "force":
                # gain R_WM^T f_WE / scale, row by row.
                x, y, z = slave
                factor = gain * self._inverse_scale
                force = [factor * (r0 * x + r1 * y + r2 * z) for r0, r1, r2 in self._RT_rows]
            else:
                p_MS = _vector(self._inputs["p_MS"], context, "p_MS")
                v_MS = _vector(self._inputs["v_MS"], context, "v_MS")
                dp = [p - o for p, o in zip(slave[:3], self._p_WMo)]
                dv = slave[3:]
                force = []
                for (r0, r1, r2), p, v in zip(self._RT_rows, p_MS, v_MS):
                    error = (r0 * dp[0] + r1 * dp[1] + r2 * dp[2]) / self._scale - p
                    error_rate = (r0 * dv[0] + r1 * dv[1] + r2 * dv[2]) / self._scale - v
                    force.append(stiffness * error + damping * error_rate)
            return saturate_norm(force, peak_force)

        def _passive_force(self, context):
            """(force, v_MS, E): the force after the passivity controller, if any."""
            force = self._force(context, self._slave_sample(context))
            if self._passivity == "none":
                return force, None, None
            if not self._inputs["v_MS"].HasValue(context):
                raise ValueError(
                    "passivity 'tdpa' needs the stylus velocity: connect the master's v_MS "
                    "to the force feedback's v_MS input"
                )
            v_MS = _vector(self._inputs["v_MS"], context, "v_MS")
            energy = self._state_values(context)[-1]
            force, _ = passivity_step(force, v_MS, energy, self._period)
            return saturate_norm(force, self.gains(context)[3]), v_MS, energy

        def _initialize(self, context, discrete_state):
            # Before the start the slave was at rest where it starts: the delay holds that.
            discrete_state.set_value(self._state, np.array(self._live_sample(context) + [0.0]))

        def _update(self, context, discrete_state):
            force, v_MS, energy = self._passive_force(context)
            energy = energy - self._period * sum(f * v for f, v in zip(force, v_MS))
            state = self._state_values(context)
            discrete_state.set_value(self._state, np.array(state[:-1] + [energy]))

        def energy(self, context):
            """The passivity observer's energy E (J): what the channel took from the master."""
            if not self.stateful:
                raise ValueError("energy needs delay_steps > 0 or passivity 'tdpa' (a state)")
            return self._state_values(context)[-1]

        def _calc_motor_force(self, context, output):
            output.SetFromVector(np.array(self._passive_force(context)[0]))

        def _calc_energy(self, context, output):
            output.SetAtIndex(0, self._state_values(context)[-1])

    return Impl


FeedbackLaw = FeedbackLaw_[None]


class ForceFeedback(Diagram):
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

    Two modes, chosen by ``config.mode``; only that mode's input ports exist.

    - ``"force"`` (default): ``f_WE`` (3, N) is the force the environment exerts on the
      slave end-effector E, in W (a contact force, or the tracking force of eq. 23). The
      operator feels it rotated into M and scaled back by the workspace map,
      F_m = gain * R_WM^T f_WE / scale (see :class:`WorkspaceMapping`).
    - ``"position_error"``: the paper's master PD, F_m = K_pm e + K_dm edot (Table I:
      K_pm = K_dm = 50), with e = p_MSdes - p_MS the gap between the slave's position
      mapped into M and the stylus, edot the same for velocities. Inputs: ``p_WE`` (3, m)
      and ``v_WE`` (3, m/s) the slave end-effector in W, ``p_MS`` and ``v_MS`` the stylus
      in M. Sampled with the 1 kHz master, K_dm * period / mass must stay below 2 (it is
      1.1 with Table I's 50 N s/m on the 45 g tip).

    ``motor_force`` (3, N, in M) is saturated in norm at ``config.peak_force`` (7.9 N,
    Touch X), as the device driver would. By default (``delay_steps`` = 0, ``passivity`` =
    "none") the output is a direct feedthrough of the inputs, without state; the
    HapticMaster samples it at its own rate. NaN inputs raise ValueError.

    Delay and passivity (``docs/studies.md``). ``config.delay_steps`` = n > 0 delays the
    slave's side of the inputs (``f_WE``, or ``p_WE`` and ``v_WE``) by n samples of
    ``period`` through Drake's ``DiscreteTimeDelay``: the slave-to-master half of the
    teleoperation channel (the workspace map delays the master-to-slave half). The output
    at sample k uses the slave's values of sample k - n (before the start: the values at
    initialisation, the slave at rest; the delay carries a validity flag beside the
    sample) and the master's of sample k. ``config.passivity`` = "tdpa" adds the
    time-domain passivity observer and controller of Hannaford & Ryu (2002) at the
    master's port (:func:`passivity_step`, the energy in a discrete state updated every
    ``period``; in mode "force" it needs the ``v_MS`` input), applied after the
    saturation, whose result is saturated again; the observer sums the force actually
    applied. The gains and the limit live in the Context (a numeric parameter of the law,
    initially the config's): :meth:`set_gains` changes them in one context.

    Structure: [``Multiplexer`` (slave sample, constant 1) -> ``DiscreteTimeDelay``] ->
    :class:`FeedbackLaw` (a scalar-convertible LeafSystem: double and AutoDiffXd, every
    mode and the passivity controller, whose switch is piecewise differentiable).

    Parameters
    ----------
    mapping : WorkspaceMapping
    period : float
        Sample period of the delay and the passivity controller (s): the master's.
    config : FeedbackConfig
        mode, gain, stiffness (K_pm, N/m), damping (K_dm, N s/m), peak_force (N),
        delay_steps, passivity.
    """

    def __init__(self, *, mapping, period, config=FeedbackConfig()):
        Diagram.__init__(self)
        if not isinstance(mapping, WorkspaceMapping):
            raise ValueError(f"mapping must be a WorkspaceMapping, got {type(mapping).__name__}")
        if config.mode not in FEEDBACK_MODES:
            raise ValueError(f"mode must be one of {FEEDBACK_MODES}, got {config.mode!r}")
        if config.passivity not in FEEDBACK_PASSIVITY:
            raise ValueError(
                f"passivity must be one of {FEEDBACK_PASSIVITY}, got {config.passivity!r}"
            )
        steps = config.delay_steps
        if isinstance(steps, bool) or int(steps) != steps or steps < 0:
            raise ValueError(f"delay_steps must be a non-negative integer, got {steps!r}")
        self.mapping = mapping
        self.mode = config.mode
        self.delay_steps = int(steps)
        builder = DiagramBuilder()
        law = builder.AddNamedSystem(
            "law", FeedbackLaw(mapping=mapping, period=period, config=config)
        )
        self._law = law
        self.stateful = law.stateful
        names = [law.get_input_port(i).get_name() for i in range(law.num_input_ports())]
        slave_names = [name for name in ("f_WE", "p_WE", "v_WE") if name in names]
        for name in names:
            if name != "delayed":
                builder.ExportInput(law.GetInputPort(name), name)
        if self.delay_steps:
            join = builder.AddNamedSystem("join", Multiplexer([3] * len(slave_names) + [1]))
            valid = builder.AddNamedSystem("valid", ConstantVectorSource([1.0]))
            delay = builder.AddNamedSystem(
                "delay",
                DiscreteTimeDelay(
                    as_scalar("period", period), self.delay_steps - 1, 3 * len(slave_names) + 1
                ),
            )
            for i, name in enumerate(slave_names):
                builder.ConnectInput(name, join.get_input_port(i))
            builder.Connect(valid.get_output_port(), join.get_input_port(len(slave_names)))
            builder.Connect(join.get_output_port(), delay.get_input_port())
            builder.Connect(delay.get_output_port(), law.GetInputPort("delayed"))
        builder.ExportOutput(law.GetOutputPort("motor_force"), "motor_force")
        if law.HasOutputPort("energy"):
            builder.ExportOutput(law.GetOutputPort("energy"), "energy")
        builder.BuildInto(self)

    def set_gains(self, context, *, gain=None, stiffness=None, damping=None, peak_force=None):
        """Change the gains or the limit in ``context`` (this diagram's): the numeric
        parameter [gain, K_pm, K_dm, peak_force] of the law; None keeps a value."""
        law_context = self.GetMutableSubsystemContext(self._law, context)
        parameter = law_context.get_mutable_numeric_parameter(0)
        for i, value in enumerate((gain, stiffness, damping, peak_force)):
            if value is not None:
                parameter.SetAtIndex(i, value)

    def energy(self, context):
        """The passivity observer's energy E (J) in ``context`` (this diagram's)."""
        return self._law.energy(self.GetSubsystemContext(self._law, context))
