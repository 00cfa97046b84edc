"""A person at the controls: teleoperate the demonstration diagram from Drake's Meshcat page.

:class:`BrowserMaster` stands where the :class:`~hemg_drake.teleop.operator.SimulatedOperator`
stands, in front of the same ``HapticMaster`` (eq. 19), workspace map, CLIK, variable-gain PD
and scene. Every ``period`` (10 ms) it samples the operator's raw inputs from an input source
(:mod:`hemg_drake.teleop.browser_inputs`: the live page's keyboard sliders and gamepad, or an
inputs log that re-drives a take bit for bit).

A virtual hand, the simulated operator's impedance (``scenario.operator``: hand_stiffness,
hand_damping, max_hand_force), pulls the stylus towards the target, so the master's
dynamics and the force feedback still act; the activation feeds the sEMG source and chain
of a demonstration. The page is :mod:`hemg_drake.teleop.browser_page`'s; a take's run loop
and its run folder are the application's (:mod:`hemg_drake.teleop_session`).

Everything the master knows lives in its Context: the target and activation (discrete
state), and the samples so far with the take's end state and the messages for the terminal
(abstract state, :class:`SampledInputs`). So two contexts of one diagram hold independent
inputs logs, and ``Clone()`` works (the clone shares the read-only input source).
"""

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake._validate import as_scalar, as_vector
from hemg_drake.teleop.browser_inputs import (
    COLUMN_INDEX,
    COLUMNS,
    FINE,
    FINE_BUTTON,
    KEY_SPEED,
    N_AXES,
    TRIGGER_BUTTON,
)
from hemg_drake.teleop.master import TOUCH_X_WORKSPACE
from hemg_drake.teleop.operator import (
    HAND_DAMPING,
    HAND_STIFFNESS,
    MAX_HAND_FORCE,
    hand_impedance_force,
)

# The take ends when no page has been open for this long after one was (s, simulated).
CLOSED_PAGE_TIMEOUT = 2.0


def _value(x):
    """A float, or an AutoDiffXd's value."""
    return x if isinstance(x, float) else x.value()


def dead_zone(value, width):
    """A stick axis with its dead zone removed: 0 within ``width``, rescaled to [-1, 1]
    beyond it (continuous at the edge). NaN reads as 0 (a stick left alone)."""
    if not math.isfinite(value) or abs(value) <= width:
        return 0.0
    magnitude = (min(abs(value), 1.0) - width) / (1.0 - width)
    return math.copysign(magnitude, value)


class SampledInputs:
    """The inputs sampled so far, newest first, and what they tell (immutable).

    A persistent list: each sample points at the older ones, so appending one is O(1) and
    the abstract state holding the newest is copied in O(1) per sample (``copy.deepcopy``,
    which Drake's Python values use, returns it unchanged: nothing in it can change).

    Attributes
    ----------
    count : int, the number of samples; time : float, the newest sample's time (s,
    simulated); wall_time : float, its wall clock (s); row : tuple of len(COLUMNS) floats;
    previous : SampledInputs or None; first_end_clicks : float, the End button's clicks at
    the first sample; last_open : float or None, the last sample time with a page open;
    gamepad, gamepad_nan : whether the newest sample had a gamepad (None before any) and
    the gamepad's NaN status as last seen; messages : tuple of str, for the terminal, one
    per transition of the gamepad (connected, gone, NaN).
    """

    __slots__ = ("count", "time", "wall_time", "row", "previous", "first_end_clicks",
                 "last_open", "gamepad", "gamepad_nan", "messages")  # fmt: skip

    def __init__(self, **values):
        for name in self.__slots__:
            object.__setattr__(self, name, values[name])

    def __setattr__(self, name, value):
        raise AttributeError("SampledInputs is immutable")

    def __copy__(self):
        return self

    def __deepcopy__(self, memo):
        return self

    def appended(self, t, wall_time, row):
        """These samples and one more at ``t`` (s) of ``row`` (len(COLUMNS) floats)."""
        index = row[COLUMN_INDEX["gamepad_index"]]
        present = index >= 0
        messages = []
        if present and not self.gamepad:
            messages.append(f"t = {t:.2f} s: gamepad {int(index)} connected")
        elif self.gamepad and not present:
            messages.append(
                f"t = {t:.2f} s: the gamepad disconnected: the target holds; keyboard still works"
            )
        nan = self.gamepad_nan
        if present:
            values = [row[COLUMN_INDEX[f"axis_{i}"]] for i in range(N_AXES)]
            values.append(row[COLUMN_INDEX[f"button_{TRIGGER_BUTTON}"]])
            nan = any(math.isnan(v) for v in values)
            if nan and not self.gamepad_nan:
                messages.append(f"t = {t:.2f} s: the gamepad sent NaN axes: read as 0")
        clicks = row[COLUMN_INDEX["end_clicks"]]
        return SampledInputs(
            count=self.count + 1, time=t, wall_time=wall_time, row=tuple(row), previous=self,
            first_end_clicks=clicks if self.count == 0 else self.first_end_clicks,
            last_open=t if row[COLUMN_INDEX["connections"]] > 0 else self.last_open,
            gamepad=present, gamepad_nan=nan,
            messages=self.messages + tuple(messages) if messages else self.messages,
        )  # fmt: skip

    def end_reason(self):
        """Why the take should end after these samples, or None: "button" (End take or
        Escape), "page closed" (pages were open, none for ``CLOSED_PAGE_TIMEOUT`` s)."""
        if self.count == 0:
            return None
        if self.row[COLUMN_INDEX["end_clicks"]] > self.first_end_clicks:
            return "button"
        if self.last_open is not None and self.time - self.last_open >= CLOSED_PAGE_TIMEOUT:
            return "page closed"
        return None

    def to_arrays(self):
        """(times (N,), wall_times (N,), rows (N, len(COLUMNS))) in sampling order."""
        samples, node = [], self
        while node.count > 0:
            samples.append(node)
            node = node.previous
        samples.reverse()
        times = np.array([s.time for s in samples], dtype=float)
        walls = np.array([s.wall_time for s in samples], dtype=float)
        rows = np.array([s.row for s in samples], dtype=float).reshape(-1, len(COLUMNS))
        return times, walls, rows


NO_SAMPLES = SampledInputs(count=0, time=math.nan, wall_time=math.nan, row=(), previous=None,
                           first_end_clicks=math.nan, last_open=None, gamepad=None,
                           gamepad_nan=False, messages=())  # fmt: skip


@TemplateSystem.define("BrowserMaster_", T_list=[float, AutoDiffXd])
def BrowserMaster_(T):
    class Impl(LeafSystem_[T]):
        """A person's hand at the stylus, from keyboard and gamepad inputs on the Meshcat page.

        .. pydrake_system::

            name: BrowserMaster
            input_ports:
            - p_MS
            - v_MS
            - feedback_force
            output_ports:
            - hand_force
            - activation
            - p_MT
            - assist_on

        Ports as the SimulatedOperator's (so ``build_demonstration_diagram(operator_factory=)``
        swaps it in): ``p_MS`` (3, m) and ``v_MS`` (3, m/s) the stylus tip in M;
        ``feedback_force`` (3, N, in M) the device motors' force, read by nothing (a keyboard
        renders no force: the page shows the slave's force instead); ``hand_force`` (3, N, in
        M) for the HapticMaster; ``activation`` (1, in [0, 1]) for the sEMG source; ``p_MT``
        (3, m) the stylus target in M (for the page); ``assist_on`` (1) the person's assist
        switch (1 on, 0 off; the arbitration's ``enabled``).

        Timing: every ``period`` (10 ms, from t = 0) a periodic unrestricted update reads one
        raw row (:data:`COLUMNS`) and its wall time from ``source`` into the abstract state
        (:class:`SampledInputs`: the inputs log, the End clicks, the last time a page was
        open, the terminal's messages); then, at the same time, a periodic discrete update
        steps the target p_T, its velocity v_T and the activation a from that row (so the
        other systems' updates at that time see the previous sample, as from any discrete
        system):

        - keyboard: s_k = s_(k-1) + clip(s*_k - s_(k-1), +-T v_key), the set-point
          s*_k = p_MS_initial + (slider - slider at the first sample) (mm to m) approached at
          no more than ``key_speed`` per axis (a non-finite slider value holds that axis);
        - gamepad: displacement g_k = clip(s_k + g_(k-1) + T v_pad, box) - s_k with
          v_pad = speed [dz(axis 0), -dz(axis 3), dz(axis 1)] (dz: :func:`dead_zone`; sticks
          up are negative; ``speed`` times ``FINE``, a quarter, while the left bumper,
          button 4, is held), so p_T = s + g stays in the workspace box and v_T = (g_k -
          g_(k-1)) / T;
        - a = clip(max(activation slider, trigger), 0, 1) (the trigger is button 7);
        - assist_on = 1 if (assist clicks - those at the first sample) is even, else 0.

        The hand is the simulated operator's impedance towards the target (eq. 19's F_h):
        ``hand_force = sat(K_h (p_T - p_MS) + D_h (v_T - v_MS), max_hand_force)``, a direct
        feedthrough of ``p_MS`` and ``v_MS``. A missing gamepad (none yet, or disconnected:
        the page sends no axes) moves nothing; a NaN axis or trigger reads as 0; each
        transition is one message (:meth:`messages`).

        Scalar types: double and AutoDiffXd (``Clone()`` goes through AutoDiffXd; the hand
        force is differentiable in p_MS, v_MS and the state; the rows read are constants).
        A clone shares ``source``, which reading does not change (a live page's clone reads
        the same page); everything sampled lives in each context.

        Parameters
        ----------
        source : MeshcatInputs or LoggedInputs
            Anything with ``read(t) -> (list of len(COLUMNS) floats, wall time)``.
        p_MS_initial : 3 floats, m
            Where the stylus starts (the target's start).
        workspace_size : 3 floats, m
            The box centred on M's origin that holds the target (the Touch X's).
        hand_stiffness, hand_damping, max_hand_force : float
            The virtual hand (N/m, N s/m, N): ``scenario.operator``'s.
        speed : float
            Target speed at full stick deflection (m/s).
        key_speed : float
            The fastest the keyboard's part of the target moves, per axis (m/s).
        stick_dead_zone : float
            Dead zone of the sticks, in [0, 1).
        period : float
            Input sampling period (s); 0.01 logs the inputs at 100 Hz.
        initial_activation : float
            The activation before the first sample, in [0, 1].
        """

        def _construct(
            self,
            *,
            source,
            p_MS_initial,
            workspace_size=TOUCH_X_WORKSPACE,
            hand_stiffness=HAND_STIFFNESS,
            hand_damping=HAND_DAMPING,
            max_hand_force=MAX_HAND_FORCE,
            speed=0.1,
            stick_dead_zone=0.15,
            period=0.01,
            initial_activation=0.05,
            key_speed=KEY_SPEED,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            self._arguments = dict(
                source=source, p_MS_initial=p_MS_initial, workspace_size=workspace_size,
                hand_stiffness=hand_stiffness, hand_damping=hand_damping,
                max_hand_force=max_hand_force, speed=speed, stick_dead_zone=stick_dead_zone,
                period=period, initial_activation=initial_activation, key_speed=key_speed,
            )  # fmt: skip
            if not callable(getattr(source, "read", None)):
                raise ValueError(
                    "source must have a read(t) method (MeshcatInputs, LoggedInputs)"
                )
            self.source = source
            self.p_MS_initial = as_vector("p_MS_initial", p_MS_initial, 3).tolist()
            half = (as_vector("workspace_size", workspace_size, 3) / 2).tolist()
            if min(half) <= 0:
                raise ValueError(f"workspace_size must be positive, got {workspace_size}")
            if any(abs(p) > h for p, h in zip(self.p_MS_initial, half)):
                raise ValueError(
                    f"p_MS_initial {self.p_MS_initial} must be inside the workspace box "
                    f"{half} (m)"
                )
            self.half_size = half
            self.hand_stiffness = as_scalar("hand_stiffness", hand_stiffness, strict=False)
            self.hand_damping = as_scalar("hand_damping", hand_damping, strict=False)
            self.max_hand_force = as_scalar("max_hand_force", max_hand_force, strict=False)
            self.speed = as_scalar("speed", speed, strict=False)
            self.stick_dead_zone = as_scalar("stick_dead_zone", stick_dead_zone, strict=False)
            if self.stick_dead_zone >= 1.0:
                raise ValueError(f"stick_dead_zone must be in [0, 1), got {stick_dead_zone}")
            self.period = as_scalar("period", period)
            self.key_speed = as_scalar("key_speed", key_speed)
            self.key_limit = self.key_speed * self.period
            initial_activation = as_scalar("initial_activation", initial_activation,
                                           strict=False)  # fmt: skip
            if initial_activation > 1.0:
                raise ValueError(
                    f"initial_activation must be in [0, 1], got {initial_activation}"
                )

            self._p_MS_input = self.DeclareVectorInputPort("p_MS", 3)
            self._v_MS_input = self.DeclareVectorInputPort("v_MS", 3)
            self.DeclareVectorInputPort("feedback_force", 3)
            # Discrete state: target p_T (3), its velocity v_T (3), gamepad displacement g
            # (3), activation (1), first keyboard slider values (3), a "sampled" flag (1),
            # the assist button's first clicks (1) and the assist switch (1, on at first).
            self.initial_state = [*self.p_MS_initial, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                  initial_activation, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]  # fmt: skip
            self._state_index = self.DeclareDiscreteState(self.initial_state)
            self._samples_index = self.DeclareAbstractState(AbstractValue.Make(NO_SAMPLES))
            self.DeclarePeriodicUnrestrictedUpdateEvent(
                period_sec=self.period, offset_sec=0.0, update=self._sample
            )
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=self.period, offset_sec=0.0, update=self._update
            )
            state_ticket = self.discrete_state_ticket(self._state_index)
            self.DeclareVectorOutputPort(
                "hand_force",
                3,
                self._calc_hand_force,
                prerequisites_of_calc={
                    state_ticket,
                    self._p_MS_input.ticket(),
                    self._v_MS_input.ticket(),
                },
            )
            self.DeclareVectorOutputPort(
                "activation", 1, self._calc_activation, prerequisites_of_calc={state_ticket}
            )
            self.DeclareVectorOutputPort(
                "p_MT", 3, self._calc_target, prerequisites_of_calc={state_ticket}
            )
            self.DeclareVectorOutputPort(
                "assist_on", 1, self._calc_assist_on, prerequisites_of_calc={state_ticket}
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._arguments, converter=converter)

        # -- the laws ---------------------------------------------------------------------
        def step(self, row, state):
            """The state after one sample of ``row`` (both lists of floats): the update's
            maths."""
            col = COLUMN_INDEX
            first, setpoints, s_olds = self.setpoints(row, state)
            s = []
            for s_old, setpoint in zip(s_olds, setpoints):
                # The slider's set-point, reached at no more than key_speed: a stall of the
                # simulation (keys moved on in wall time) never becomes a jump.
                step = setpoint - s_old
                s.append(s_old + min(max(step, -self.key_limit), self.key_limit))
            g_old = state[6:9]
            dz = self.stick_dead_zone
            if row[col["gamepad_index"]] >= 0:
                ax = [row[col[f"axis_{i}"]] for i in range(N_AXES)]
                # The left bumper held: fine motion, as Shift on the keyboard.
                fine = row[col[f"button_{FINE_BUTTON}"]]
                speed = self.speed * (FINE if math.isfinite(fine) and fine > 0.5 else 1.0)
                v_pad = [
                    speed * dead_zone(ax[0], dz),
                    -speed * dead_zone(ax[3], dz),
                    speed * dead_zone(ax[1], dz),
                ]
                trigger = row[col[f"button_{TRIGGER_BUTTON}"]]
                trigger = trigger if math.isfinite(trigger) else 0.0
            else:
                v_pad, trigger = [0.0, 0.0, 0.0], 0.0
            p_T, g = [], []
            for si, gi, vi, h in zip(s, g_old, v_pad, self.half_size):
                p = min(max(si + gi + self.period * vi, -h), h)
                p_T.append(p)
                g.append(p - si)
            v_T = [(gn - go) / self.period for gn, go in zip(g, g_old)]
            slider = row[col["slider_activation"]]
            slider = slider if math.isfinite(slider) else 0.0
            activation = min(max(slider, trigger, 0.0), 1.0)
            # The assist switch: on at first, each click of the page's Assist button (A)
            # toggles it (a non-finite count holds it).
            clicks = row[col["assist_clicks"]]
            first_clicks, on = state[14], state[15]
            if math.isfinite(clicks):
                first_clicks = clicks if state[13] == 0.0 else first_clicks
                on = 1.0 if (clicks - _value(first_clicks)) % 2 == 0 else 0.0
            return [*p_T, *v_T, *g, activation, *first, 1.0, first_clicks, on]

        def setpoints(self, row, state):
            """The keyboard's zero, set-point and last position after ``state`` for ``row``
            (lists of 3): s* = p_MS_initial + (slider - slider at the first sample) (mm to
            m); a non-finite slider holds that axis (s* = the last position)."""
            col = COLUMN_INDEX
            sliders = [row[col["slider_x_mm"]], row[col["slider_y_mm"]],
                       row[col["slider_z_mm"]]]  # fmt: skip
            # The first sample's slider values are the keyboard's zero.
            first = list(sliders if state[13] == 0.0 else state[10:13])
            setpoints, s_olds = [], []
            for i, (p0, value) in enumerate(zip(self.p_MS_initial, sliders)):
                s_old = state[i] - state[6 + i]  # the keyboard's part of the last target
                s_olds.append(s_old)
                if not math.isfinite(value):  # a bogus slider message: hold that axis
                    setpoints.append(s_old)
                    continue
                if not math.isfinite(_value(first[i])):  # re-anchor the zero where the target is
                    first[i] = value - 1e3 * (s_old - p0)
                setpoints.append(p0 + 1e-3 * (value - first[i]))
            return first, setpoints, s_olds

        def command(self, context):
            """Where the newest sample sends the target, and that sample's keyboard sliders:
            (p_MC, 3 floats, m, in M; sliders, 3 floats, mm), or None before any sample.
            p_MC is the keyboard's set-point plus the gamepad's part, in the workspace box:
            the target reaches it at no more than ``key_speed`` (the page draws the stylus
            target there, and moves it at once with the sliders it has sent since)."""
            samples = self.samples(context)
            if samples.count == 0:
                return None
            state = [_value(x) for x in self._state(context)]
            row = list(samples.row)
            _, setpoints, _ = self.setpoints(row, state)
            p_MC = [min(max(s + g, -h), h)
                    for s, g, h in zip(setpoints, state[6:9], self.half_size)]  # fmt: skip
            col = COLUMN_INDEX
            sliders = [row[col[f"slider_{a}_mm"]] for a in "xyz"]
            return p_MC, sliders

        def targets(self, rows):
            """The target p_T (m) and activation after each row of ``rows`` (an inputs
            log's), by :meth:`step` from the initial state: arrays (N, 3) and (N,)."""
            state, p_T, activation = list(self.initial_state), [], []
            for row in np.asarray(rows, dtype=float).tolist():
                state = self.step(row, state)
                p_T.append(state[0:3])
                activation.append(state[9])
            return np.array(p_T, dtype=float).reshape(-1, 3), np.array(activation, dtype=float)

        def hand_force_floats(self, p_T, v_T, p_MS, v_MS):
            """The virtual hand's force (N, in M, list of 3 scalars)."""
            return hand_impedance_force(
                p_T, v_T, p_MS, v_MS, stiffness=self.hand_stiffness, damping=self.hand_damping,
                max_force=self.max_hand_force,
            )  # fmt: skip

        # -- Drake callbacks --------------------------------------------------------------
        def _sample(self, context, state):
            t = _value(context.get_time())
            row, wall_time = self.source.read(t)
            row = [float(v) for v in row]
            if len(row) != len(COLUMNS):
                raise ValueError(
                    f"an input row must have {len(COLUMNS)} values, got {len(row)}"
                )
            samples = self.samples(context).appended(t, float(wall_time), row)
            state.get_mutable_abstract_state(self._samples_index).set_value(samples)

        def _update(self, context, discrete_state):
            samples = self.samples(context)
            t = _value(context.get_time())
            if samples.time != t:  # not sampled by _sample just before
                raise RuntimeError(
                    f"BrowserMaster: no input sample at t = {t!r} s (the discrete update "
                    "runs after the sampling unrestricted update)"
                )
            state = self._state(context)
            new = self.step(list(samples.row), state)
            if T is not float:
                new = [x if isinstance(x, T) else T(x) for x in new]
            discrete_state.set_value(self._state_index, np.array(new))

        def _state(self, context):
            group = context.get_discrete_state(self._state_index)
            return (group.value() if T is float else group.CopyToVector()).tolist()

        def _calc_hand_force(self, context, output):
            state = self._state(context)
            p_MS = self._p_MS_input.Eval(context).tolist()
            v_MS = self._v_MS_input.Eval(context).tolist()
            values = p_MS + v_MS if T is float else [x.value() for x in p_MS + v_MS]
            if not all(map(math.isfinite, values)):
                raise ValueError(f"p_MS and v_MS must be finite, got {p_MS}, {v_MS}")
            force = self.hand_force_floats(state[0:3], state[3:6], p_MS, v_MS)
            output.SetFromVector(force if T is float else np.array(force))

        def _calc_activation(self, context, output):
            output.SetFromVector(np.array(self._state(context)[9:10]))

        def _calc_target(self, context, output):
            output.SetFromVector(np.array(self._state(context)[0:3]))

        def _calc_assist_on(self, context, output):
            output.SetFromVector(np.array(self._state(context)[15:16]))

        # -- what this context's take holds -----------------------------------------------
        def samples(self, context):
            """The :class:`SampledInputs` of ``context`` (this system's)."""
            return context.get_abstract_state(self._samples_index).get_value()

        def inputs_log(self, context):
            """(times, wall_times, rows) sampled in ``context``: the take's inputs log."""
            return self.samples(context).to_arrays()

        def messages(self, context):
            """Every message of ``context``'s take so far, in order (tuple of str)."""
            return self.samples(context).messages

        def end_reason(self, context):
            """Why ``context``'s take should end, or None (:meth:`SampledInputs.end_reason`)."""
            return self.samples(context).end_reason()

    return Impl


BrowserMaster = BrowserMaster_[None]
