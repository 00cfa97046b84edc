"""A person at the controls: teleoperate the demonstration diagram from Drake's Meshcat page.

:class:`BrowserMaster` stands where the :class:`~hemg_drake.teleop.operator.SimulatedOperator`
stands, in front of the same ``HapticMaster`` (eq. 19), workspace map, CLIK, variable-gain PD
and scene. Every ``period`` (10 ms) it samples the operator's raw inputs from an input source:

- :class:`MeshcatInputs`: the live page. Keyboard through Meshcat sliders with key bindings
  (:data:`KEYS`), limited to the Touch X's 160 x 120 x 120 mm workspace, and two keys for the
  muscle activation; a gamepad through ``Meshcat.GetGamepad()`` (left stick x/y and right
  stick y move the stylus target as velocities with a dead zone, the right trigger, button
  7, is the activation); the "End take" button (Escape) and the number of open pages.
- :class:`LoggedInputs`: the same rows read back from an inputs log (:func:`save_inputs`),
  which re-drives the diagram headless to the same demonstration, bit for bit.

A virtual hand, the simulated operator's impedance (``scenario.operator``: hand_stiffness,
hand_damping, max_hand_force), pulls the stylus towards the target, so the master's
dynamics and the force feedback still act; the activation feeds the sEMG source and chain
of a demonstration. :func:`run_take` runs one take (live at real time with the page of
:class:`TeleopPage`, or replayed); :func:`teleop` appends takes to a run folder's dataset.
"""

import contextlib
import dataclasses as dc
import logging
import math
import os
import signal
import subprocess
import time

import numpy as np
from pydrake.geometry import Cylinder, Meshcat, MeshcatCone, MeshcatParams, Rgba, Sphere
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import LeafSystem

from hemg_drake._validate import as_scalar, as_vector
from hemg_drake.fileio import load_npz, save_npz_atomic
from hemg_drake.teleop.master import TOUCH_X_WORKSPACE
from hemg_drake.teleop.operator import (
    HAND_DAMPING,
    HAND_STIFFNESS,
    MAX_HAND_FORCE,
    hand_impedance_force,
)
from hemg_drake.viz.screenshot import QUIET_FLAGS, WEBGL_FLAGS, find_chromium, remove_profile

# Slider names on the page and their key bindings (javascript KeyboardEvent.code values);
# M's axes are OpenHaptics': x to the operator's right, y up, z towards the operator.
SLIDER_X, SLIDER_Y, SLIDER_Z = "stylus x (mm)", "stylus y (mm)", "stylus z (mm)"
SLIDER_ACTIVATION = "activation"
END_BUTTON = "End take"
KEYS = {
    SLIDER_X: ("ArrowLeft", "ArrowRight"),  # left / right
    SLIDER_Y: ("KeyS", "KeyW"),  # down / up
    SLIDER_Z: ("ArrowUp", "ArrowDown"),  # away from / towards the operator
    SLIDER_ACTIVATION: ("KeyZ", "KeyX"),  # relax / tense
}
END_KEY = "Escape"
# One key press moves the target this far (mm); held keys repeat at the browser's rate.
KEY_STEP_MM = 2.0
ACTIVATION_STEP = 0.05
# Read-only sliders that show what the hand cannot feel.
# (Meshcat shows about 14 characters of a control's name.)
SHOW_FORCE, SHOW_GAIN = "force f_WE (N)", "gain K"
SHOW_TIME, SHOW_RECORDING = "time (s)", "recording"
MAX_SHOWN_FORCE = 60.0

# Columns of one raw input row, as logged.
N_AXES, N_BUTTONS = 4, 17  # the W3C standard gamepad mapping
TRIGGER_BUTTON = 7
COLUMNS = (
    "slider_x_mm", "slider_y_mm", "slider_z_mm", "slider_activation", "gamepad_index",
    *(f"axis_{i}" for i in range(N_AXES)), *(f"button_{i}" for i in range(N_BUTTONS)),
    "end_clicks", "connections",
)  # fmt: skip
_COL = {name: i for i, name in enumerate(COLUMNS)}
INPUTS_FORMAT = 1
# The take ends when no page has been open for this long after one was (s, simulated).
CLOSED_PAGE_TIMEOUT = 2.0
# The page is refreshed, and the simulator advanced, in steps of this (s): 32 Hz.
PAGE_PERIOD = 1 / 32


def dead_zone(value, width):
    """A stick axis with its dead zone removed: 0 within ``width``, rescaled to [-1, 1]
    beyond it (continuous at the edge). NaN reads as 0 (a stick left alone)."""
    if not math.isfinite(value) or abs(value) <= width:
        return 0.0
    magnitude = (min(abs(value), 1.0) - width) / (1.0 - width)
    return math.copysign(magnitude, value)


class BrowserMaster(LeafSystem):
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

    Ports as the SimulatedOperator's (so ``build_demonstration_diagram(operator_factory=)``
    swaps it in): ``p_MS`` (3, m) and ``v_MS`` (3, m/s) the stylus tip in M;
    ``feedback_force`` (3, N, in M) the device motors' force, read by nothing (a keyboard
    renders no force: the page shows the slave's force instead); ``hand_force`` (3, N, in M)
    for the HapticMaster; ``activation`` (1, in [0, 1]) for the sEMG source; ``p_MT`` (3, m)
    the stylus target in M (for the page).

    Every ``period`` a discrete update reads one raw row (:data:`COLUMNS`) from ``source``
    and sets the target p_T, its velocity v_T and the activation a:

    - keyboard: s = p_MS_initial + (slider - slider at the first sample), in m (a
      non-finite slider value holds that axis);
    - gamepad: displacement g_k = clip(s_k + g_(k-1) + T v_pad, box) - s_k with
      v_pad = speed [dz(axis 0), -dz(axis 3), dz(axis 1)] (dz: :func:`dead_zone`; sticks
      up are negative), so p_T = s + g stays in the workspace box and v_T = (g_k -
      g_(k-1)) / T;
    - a = clip(max(activation slider, trigger), 0, 1) (the trigger is button 7).

    The hand is the simulated operator's impedance towards the target (eq. 19's F_h):
    ``hand_force = sat(K_h (p_T - p_MS) + D_h (v_T - v_MS), max_hand_force)``, a direct
    feedthrough of ``p_MS`` and ``v_MS``. A missing gamepad (none yet, or disconnected: the
    page sends no axes) moves nothing; a NaN axis or trigger reads as 0; each transition is
    reported once through :meth:`pop_messages`.

    Parameters
    ----------
    source : MeshcatInputs or LoggedInputs
        Anything with ``read(t) -> list of len(COLUMNS) floats``.
    p_MS_initial : 3 floats, m
        Where the stylus starts (the target's start).
    workspace_size : 3 floats, m
        The box centred on M's origin that holds the target (the Touch X's).
    hand_stiffness, hand_damping, max_hand_force : float
        The virtual hand (N/m, N s/m, N): ``scenario.operator``'s.
    speed : float
        Target speed at full stick deflection (m/s).
    stick_dead_zone : float
        Dead zone of the sticks, in [0, 1).
    period : float
        Input sampling period (s); 0.01 logs the inputs at 100 Hz.
    """

    def __init__(
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
    ):
        LeafSystem.__init__(self)
        if not callable(getattr(source, "read", None)):
            raise ValueError("source must have a read(t) method (MeshcatInputs, LoggedInputs)")
        self.source = source
        self.p_MS_initial = as_vector("p_MS_initial", p_MS_initial, 3).tolist()
        half = (as_vector("workspace_size", workspace_size, 3) / 2).tolist()
        if min(half) <= 0:
            raise ValueError(f"workspace_size must be positive, got {workspace_size}")
        if any(abs(p) > h for p, h in zip(self.p_MS_initial, half)):
            raise ValueError(
                f"p_MS_initial {self.p_MS_initial} must be inside the workspace box {half} (m)"
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
        initial_activation = as_scalar("initial_activation", initial_activation, strict=False)
        if initial_activation > 1.0:
            raise ValueError(f"initial_activation must be in [0, 1], got {initial_activation}")
        self.rows = []  # (t, row) of every sample, in order
        self._messages = []
        self._status = {"gamepad": None, "nan": False}
        self._last_open = None  # the last sample time with a page open

        self._p_MS_input = self.DeclareVectorInputPort("p_MS", 3)
        self._v_MS_input = self.DeclareVectorInputPort("v_MS", 3)
        self.DeclareVectorInputPort("feedback_force", 3)
        # State: target p_T (3), its velocity v_T (3), gamepad displacement g (3),
        # activation (1), first keyboard slider values (3) and a "sampled" flag (1).
        initial = [*self.p_MS_initial, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, initial_activation,
                   0.0, 0.0, 0.0, 0.0]  # fmt: skip
        self._state_index = self.DeclareDiscreteState(initial)
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=self.period, offset_sec=0.0, update=self._update
        )
        self.DeclareVectorOutputPort(
            "hand_force",
            3,
            self._calc_hand_force,
            prerequisites_of_calc={
                self.xd_ticket(),
                self._p_MS_input.ticket(),
                self._v_MS_input.ticket(),
            },
        )
        self.DeclareVectorOutputPort(
            "activation", 1, self._calc_activation, prerequisites_of_calc={self.xd_ticket()}
        )
        self.DeclareVectorOutputPort(
            "p_MT", 3, self._calc_target, prerequisites_of_calc={self.xd_ticket()}
        )

    # -- the laws -------------------------------------------------------------------------
    def step(self, row, state):
        """The state after one sample of ``row`` (both lists of floats): the update's maths."""
        col = _COL
        sliders = [row[col["slider_x_mm"]], row[col["slider_y_mm"]], row[col["slider_z_mm"]]]
        # The first sample's slider values are the keyboard's zero.
        first = sliders if state[13] == 0.0 else state[10:13]
        g_old = state[6:9]
        s = []
        for i, (p0, value) in enumerate(zip(self.p_MS_initial, sliders)):
            s_old = state[i] - g_old[i]  # the keyboard's part of the last target
            if not math.isfinite(value):  # a bogus slider message: hold that axis
                s.append(s_old)
                continue
            if not math.isfinite(first[i]):  # re-anchor the zero where the target is
                first[i] = value - 1e3 * (s_old - p0)
            s.append(p0 + 1e-3 * (value - first[i]))
        dz = self.stick_dead_zone
        if row[col["gamepad_index"]] >= 0:
            ax = [row[col[f"axis_{i}"]] for i in range(N_AXES)]
            v_pad = [
                self.speed * dead_zone(ax[0], dz),
                -self.speed * dead_zone(ax[3], dz),
                self.speed * dead_zone(ax[1], dz),
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
        return [*p_T, *v_T, *g, activation, *first, 1.0]

    def hand_force_floats(self, p_T, v_T, p_MS, v_MS):
        """The virtual hand's force (N, in M, list of 3 floats)."""
        return hand_impedance_force(
            p_T, v_T, p_MS, v_MS, stiffness=self.hand_stiffness, damping=self.hand_damping,
            max_force=self.max_hand_force,
        )  # fmt: skip

    # -- Drake callbacks ------------------------------------------------------------------
    def _update(self, context, discrete_state):
        t = context.get_time()
        row = [float(v) for v in self.source.read(t)]
        if len(row) != len(COLUMNS):
            raise ValueError(f"an input row must have {len(COLUMNS)} values, got {len(row)}")
        self.rows.append((t, row))
        if row[_COL["connections"]] > 0:
            self._last_open = t
        self._note(t, row)
        state = context.get_discrete_state_vector().value().tolist()
        discrete_state.set_value(self.step(row, state))

    def _calc_hand_force(self, context, output):
        state = context.get_discrete_state_vector().value().tolist()
        p_MS = self._p_MS_input.Eval(context).tolist()
        v_MS = self._v_MS_input.Eval(context).tolist()
        if not all(map(math.isfinite, p_MS + v_MS)):
            raise ValueError(f"p_MS and v_MS must be finite, got {p_MS}, {v_MS}")
        output.SetFromVector(self.hand_force_floats(state[0:3], state[3:6], p_MS, v_MS))

    def _calc_activation(self, context, output):
        output.SetFromVector([context.get_discrete_state_vector().GetAtIndex(9)])

    def _calc_target(self, context, output):
        output.SetFromVector(context.get_discrete_state_vector().value()[0:3])

    # -- what happened --------------------------------------------------------------------
    def _note(self, t, row):
        """Queue one message per transition of the gamepad (connected, gone, NaN)."""
        index = row[_COL["gamepad_index"]]
        present = index >= 0
        was = self._status["gamepad"]
        if present and not was:
            self._messages.append(f"t = {t:.2f} s: gamepad {int(index)} connected")
        elif was and not present:
            self._messages.append(
                f"t = {t:.2f} s: the gamepad disconnected: the target holds; keyboard still works"
            )
        self._status["gamepad"] = present
        if present:
            values = [row[_COL[f"axis_{i}"]] for i in range(N_AXES)]
            values.append(row[_COL[f"button_{TRIGGER_BUTTON}"]])
            nan = any(math.isnan(v) for v in values)
            if nan and not self._status["nan"]:
                self._messages.append(f"t = {t:.2f} s: the gamepad sent NaN axes: read as 0")
            self._status["nan"] = nan

    def pop_messages(self):
        """Messages queued since the last call (list of str)."""
        messages, self._messages = self._messages, []
        return messages

    def end_reason(self):
        """Why the take should end after the rows so far, or None: "button" (End take or
        Escape), "page closed" (pages were open, none for ``CLOSED_PAGE_TIMEOUT`` s)."""
        if not self.rows:
            return None
        clicks = _COL["end_clicks"]
        if self.rows[-1][1][clicks] > self.rows[0][1][clicks]:
            return "button"
        last_open = self._last_open
        if last_open is not None and self.rows[-1][0] - last_open >= CLOSED_PAGE_TIMEOUT:
            return "page closed"
        return None


class MeshcatInputs:
    """The live input source: the page's sliders, gamepad, End button and connections.

    Adds the keyboard sliders (:data:`KEYS`; stylus position in mm, limited to the
    workspace, and the activation) and the End take button (Escape) to ``meshcat``.

    Parameters
    ----------
    meshcat : Meshcat
    p_MS_initial : 3 floats, m
        The sliders' initial values.
    workspace_size : 3 floats, m
    activation : float
        The activation slider's initial value.
    clock : callable
        Wall clock (s) logged with every row (``time.monotonic``).
    """

    def __init__(self, meshcat, *, p_MS_initial, workspace_size=TOUCH_X_WORKSPACE,
                 activation=0.05, clock=time.monotonic):  # fmt: skip
        self.meshcat = meshcat
        self.clock = clock
        self.wall_times = []
        half_mm = 500.0 * as_vector("workspace_size", workspace_size, 3)
        start_mm = 1000.0 * as_vector("p_MS_initial", p_MS_initial, 3)
        existing = set(meshcat.GetSliderNames())
        sliders = [(name, -h, h, KEY_STEP_MM, p)
                   for name, h, p in zip((SLIDER_X, SLIDER_Y, SLIDER_Z), half_mm, start_mm)]
        sliders.append((SLIDER_ACTIVATION, 0.0, 1.0, ACTIVATION_STEP, activation))
        for name, low, high, step, value in sliders:
            if name in existing:  # a second take on the same page: back to the start
                meshcat.SetSliderValue(name, value)
            else:
                down, up = KEYS[name]
                meshcat.AddSlider(name, low, high, step, value, decrement_keycode=down,
                                  increment_keycode=up)  # fmt: skip
        meshcat.AddButton(END_BUTTON, keycode=END_KEY)  # (again: resets its clicks)

    def read(self, t):
        m = self.meshcat
        row = [m.GetSliderValue(n) for n in (SLIDER_X, SLIDER_Y, SLIDER_Z, SLIDER_ACTIVATION)]
        pad = m.GetGamepad()
        axes = [math.nan] * N_AXES
        buttons = [math.nan] * N_BUTTONS
        if pad.index is None:
            index = -1.0
        else:
            index = float(pad.index)
            for i, value in enumerate(list(pad.axes)[:N_AXES]):
                axes[i] = value
            for i, value in enumerate(list(pad.button_values)[:N_BUTTONS]):
                buttons[i] = value
            if not pad.axes and not pad.button_values:
                index = -1.0  # the page sends an empty gamepad once it is disconnected
        row += [index, *axes, *buttons]
        row += [float(m.GetButtonClicks(END_BUTTON)), float(m.GetNumActiveConnections())]
        self.wall_times.append(self.clock())
        return row


class LoggedInputs:
    """An input source reading back a log's rows in order, checking each row's time.

    Parameters
    ----------
    times : array, shape (N,), s
    rows : array, shape (N, len(COLUMNS))
    """

    def __init__(self, times, rows):
        self.times = np.asarray(times, dtype=float)
        self.rows = np.asarray(rows, dtype=float)
        if self.rows.ndim != 2 or self.rows.shape[1] != len(COLUMNS):
            raise ValueError(
                f"input rows must have shape (N, {len(COLUMNS)}), got {self.rows.shape}"
            )
        if self.times.shape != (len(self.rows),):
            raise ValueError("input times must have one entry per row")
        self._next = 0

    def read(self, t):
        k = self._next
        if k >= len(self.rows):
            raise ValueError(
                f"the inputs log ends at sample {k} (t = {self.times[-1]:.3f} s) but the "
                f"diagram asks for t = {t:.3f} s: the log does not belong to this take"
            )
        if self.times[k] != t:
            raise ValueError(
                f"inputs log sample {k} is at t = {float(self.times[k])!r} s, the diagram's at "
                f"{t!r} s: "
                "recorded with another input period or scenario"
            )
        self._next = k + 1
        return self.rows[k].tolist()


@dc.dataclass(frozen=True, eq=False)
class InputsLog:
    """The raw inputs of one take: what :func:`save_inputs` writes beside it.

    Attributes
    ----------
    time : (N,) sample times (s, simulated); wall_time : (N,) wall clock at each read (s);
    rows : (N, len(COLUMNS)) raw values (NaN where a gamepad gave none);
    end_time : float, where the take ended (s); end_reason : str; seed : int;
    scenario : str, the scenario's YAML.
    """

    time: np.ndarray
    wall_time: np.ndarray
    rows: np.ndarray
    end_time: float
    end_reason: str
    seed: int
    scenario: str


def save_inputs(path, log):
    """Write an :class:`InputsLog` as NPZ, atomically (no pickles)."""
    save_npz_atomic(
        path,
        format_version=np.array(INPUTS_FORMAT),
        columns=np.array(COLUMNS),
        time=np.asarray(log.time, dtype=float),
        wall_time=np.asarray(log.wall_time, dtype=float),
        rows=np.asarray(log.rows, dtype=float).reshape(-1, len(COLUMNS)),
        end_time=np.array(float(log.end_time)),
        end_reason=np.array(str(log.end_reason)),
        seed=np.array(int(log.seed)),
        scenario=np.array(log.scenario),
    )


def load_inputs(path):
    """Read an inputs log written by :func:`save_inputs`; ValueError naming the problem."""
    arrays = load_npz(path, kind="teleop inputs log")
    needed = ("format_version", "columns", "time", "wall_time", "rows", "end_time",
              "end_reason", "seed", "scenario")  # fmt: skip
    missing = [name for name in needed if name not in arrays]
    if missing:
        raise ValueError(f"{path}: not a teleop inputs log (missing {', '.join(missing)})")
    if int(arrays["format_version"]) != INPUTS_FORMAT:
        raise ValueError(f"{path}: inputs log format {arrays['format_version']}, expected 1")
    if tuple(str(c) for c in arrays["columns"]) != COLUMNS:
        raise ValueError(f"{path}: the inputs log's columns differ from this version's")
    return InputsLog(
        time=arrays["time"], wall_time=arrays["wall_time"], rows=arrays["rows"],
        end_time=float(arrays["end_time"]), end_reason=str(arrays["end_reason"]),
        seed=int(arrays["seed"]), scenario=str(arrays["scenario"]),
    )  # fmt: skip


class TeleopPage:
    """What the hand cannot feel, on the Meshcat page: the slave's force as an arrow at the
    tool (1 cm per newton) and a bar, the gain K, the time, whether a take is recording,
    and the stylus target (a small sphere, mapped to the slave's side).

    The bar, K, time and recording flag are read-only sliders (Meshcat's controls have no
    text field); :meth:`update` sets them with ``SetSliderValue``.
    """

    PATH = "/teleop"
    ARROW_SCALE = 0.01  # m per N

    def __init__(self, meshcat, *, k_min, k_max):
        self.meshcat = meshcat
        existing = set(meshcat.GetSliderNames())
        for name, high, step, value in ((SHOW_FORCE, MAX_SHOWN_FORCE, 0.1, 0.0),
                                        (SHOW_GAIN, math.ceil(k_max), 0.1, k_min),
                                        (SHOW_TIME, 3600.0, 0.01, 0.0),
                                        (SHOW_RECORDING, 1.0, 1.0, 0.0)):  # fmt: skip
            if name in existing:
                meshcat.SetSliderValue(name, value)
            else:
                meshcat.AddSlider(name, 0.0, high, step, value)
        orange = Rgba(1.0, 0.5, 0.0, 1.0)
        # The arrow points along its frame's +z; the shaft (1 m, scaled) and the head are
        # separate paths so scaling the shaft does not stretch the head.
        meshcat.SetObject(f"{self.PATH}/force/shaft/geometry", Cylinder(0.004, 1.0), orange)
        meshcat.SetTransform(f"{self.PATH}/force/shaft/geometry", RigidTransform([0, 0, 0.5]))
        meshcat.SetObject(f"{self.PATH}/force/head", MeshcatCone(0.02, 0.01, 0.01), orange)
        meshcat.SetObject(f"{self.PATH}/target", Sphere(0.012), Rgba(0.1, 0.6, 1.0, 0.7))
        meshcat.SetProperty(f"{self.PATH}/force", "visible", False)
        meshcat.SetProperty("/Axes", "visible", False)  # the world axes hide the arm's base
        self.updates = 0

    def update(self, t, p_WE, f_WE, gain, recording, p_WT=None):
        m = self.meshcat
        f = np.asarray(f_WE, dtype=float)
        magnitude = float(np.linalg.norm(f))
        m.SetSliderValue(SHOW_FORCE, min(magnitude, MAX_SHOWN_FORCE))
        m.SetSliderValue(SHOW_GAIN, float(gain))
        m.SetSliderValue(SHOW_TIME, float(t))
        m.SetSliderValue(SHOW_RECORDING, 1.0 if recording else 0.0)
        length = self.ARROW_SCALE * magnitude
        visible = length > 1e-3
        m.SetProperty(f"{self.PATH}/force", "visible", visible)
        if visible:
            R = _rotation_z_to(f / magnitude)
            # The cone's apex is at its frame's origin and it opens along +z: turn it over.
            head = RigidTransform(R, p_WE) @ RigidTransform(
                RotationMatrix.MakeXRotation(math.pi), [0, 0, length + 0.02]
            )
            m.SetTransform(f"{self.PATH}/force/shaft", RigidTransform(R, p_WE))
            m.SetProperty(f"{self.PATH}/force/shaft", "scale", [1.0, 1.0, length])
            m.SetTransform(f"{self.PATH}/force/head", head)
        if p_WT is not None:
            m.SetTransform(f"{self.PATH}/target", RigidTransform(np.asarray(p_WT, float)))
        self.updates += 1


def _rotation_z_to(direction):
    """A rotation taking +z to the unit vector ``direction``."""
    z = np.asarray(direction, dtype=float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return RotationMatrix(np.column_stack([x, y, z]))


def start_meshcat(port):
    """A Meshcat server on localhost:``port`` (0: a free one); ValueError if it is taken."""
    port = int(port)
    if not 0 <= port <= 65535:
        raise ValueError(f"--port must be in 0..65535, got {port}")
    drake_logger = logging.getLogger("drake")
    level = drake_logger.level
    drake_logger.setLevel(logging.WARNING)  # our own first line names the URL
    try:
        return Meshcat(MeshcatParams(host="localhost", port=port))
    except RuntimeError as error:
        raise ValueError(
            f"cannot listen on localhost:{port} ({error}): the port is in use; give another "
            "--port, or --port 0 for a free one"
        ) from None
    finally:
        drake_logger.setLevel(level)


@dc.dataclass(frozen=True, eq=False)
class Take:
    """One take: its demonstration, its raw inputs, and the built diagram."""

    demonstration: object
    inputs: InputsLog
    built: object
    master: BrowserMaster
    page_updates: int
    wall_seconds: float


def run_take(scenario, *, seed, source="meshcat", meshcat=None, duration=None, realtime=True,
             recorder=None, replay_path=None, progress=print, on_step=None,
             scene=True):  # fmt: skip
    """Run one take of the demonstration diagram with a :class:`BrowserMaster`.

    Parameters
    ----------
    scenario : Scenario
    seed : int
        Seeds the sEMG noise (and the unused operator plan).
    source : "meshcat" or InputsLog
        Live inputs from ``meshcat``'s page, or a log to re-drive (headless).
    meshcat : Meshcat, optional
        The live page (needed for ``source="meshcat"``): the arm, the page's controls and
        :class:`TeleopPage`.
    duration : float, optional
        End after this many simulated seconds. With a log, its ``end_time`` is used.
    realtime : bool
        Pace the simulator at real time (``set_target_realtime_rate(1)``).
    recorder : ReplayRecorder, optional; replay_path : path-like, optional
        Record the take and write its HTML replay (with ink for drawing).
    progress : callable taking one line (the master's messages).
    on_step : callable, optional
        Called as ``on_step(t)`` after each page period (tests script the page with it).
    scene : bool
        False leaves out the task's scene (the arm in free space).

    Returns
    -------
    Take
    """
    from hemg_drake.diagrams.demonstration import (
        build_demonstration_diagram,
        demonstration_from_logs,
    )
    from hemg_drake.viz.ink import add_ink_to_recording, in_contact

    live = isinstance(source, str)
    if live and source != "meshcat":
        raise ValueError(f"source must be 'meshcat' or an InputsLog, got {source!r}")
    if live and meshcat is None:
        raise ValueError("live inputs need the meshcat whose page the person uses")
    if not live:
        duration = source.end_time
    elif duration is not None:
        duration = as_scalar("duration", duration)
    operator = scenario.operator
    holder = {}

    def factory(*, scenario, mapping, p_MS_initial, seed):
        inputs = (
            MeshcatInputs(meshcat, p_MS_initial=p_MS_initial,
                          workspace_size=scenario.master.workspace_size,
                          activation=operator.rest_activation)  # fmt: skip
            if live
            else LoggedInputs(source.time, source.rows)
        )
        holder["inputs"] = inputs
        holder["master"] = BrowserMaster(
            source=inputs, p_MS_initial=p_MS_initial,
            workspace_size=scenario.master.workspace_size,
            hand_stiffness=operator.hand_stiffness, hand_damping=operator.hand_damping,
            max_hand_force=operator.max_hand_force, initial_activation=operator.rest_activation,
        )  # fmt: skip
        return holder["master"]

    built = build_demonstration_diagram(
        scenario, seed=seed, meshcat=meshcat if live else None, recorder=recorder,
        operator_factory=factory, scene=scene,
    )  # fmt: skip
    master = holder["master"]
    page = None
    if live:
        from hemg_drake.robots.baxter import FLOOR_Z
        from hemg_drake.viz.recording import frame_task

        meshcat.SetCameraPose(*frame_task(scenario.task_plan().points))
        meshcat.SetTransform("/Grid", RigidTransform([0.0, 0.0, FLOOR_Z]))
        page = TeleopPage(meshcat, k_min=scenario.emg.k_min, k_max=scenario.emg.k_max)
    diagram = built.diagram
    simulator = Simulator(diagram)
    ApplySimulatorConfig(scenario.simulator, simulator)
    simulator.set_target_realtime_rate(1.0 if realtime else 0.0)
    simulator.Initialize()
    context = simulator.get_context()
    station = built.station.diagram
    gain_system = diagram.GetSubsystemByName("variable_gain")
    gain_port = gain_system.get_gain_output_port()
    if recorder is not None:
        recorder.start()
    began = time.perf_counter()
    k, reason, t = 0, None, 0.0
    while True:
        k += 1
        t = k * PAGE_PERIOD
        if duration is not None and t >= duration:
            t = duration
        simulator.AdvanceTo(t)
        for line in master.pop_messages():
            progress(line)
        if page is not None:
            station_context = station.GetMyContextFromRoot(context)
            p_WT = built.mapping.master_to_slave(master.GetOutputPort("p_MT").Eval(
                master.GetMyContextFromRoot(context)))  # fmt: skip
            page.update(
                t,
                station.GetOutputPort("p_WE").Eval(station_context),
                station.GetOutputPort("f_WE").Eval(station_context),
                gain_port.Eval(gain_system.GetMyContextFromRoot(context))[0],
                True,
                p_WT,
            )  # fmt: skip
        if on_step is not None:
            on_step(t)
        if duration is not None and t >= duration:
            reason = "duration"
            break
        reason = master.end_reason()
        if reason is not None and (live or t >= duration):
            break
    wall = time.perf_counter() - began
    if page is not None:
        page.update(t, np.zeros(3), np.zeros(3), scenario.emg.k_min, False)
    demo = demonstration_from_logs(
        built.logger.FindLog(context), built.emg_logger.FindLog(context), seed
    )
    if replay_path is not None:
        if scenario.task == "drawing" and built.scene is not None:
            add_ink_to_recording(recorder.meshcat, demo.time, demo.p_WE, in_contact(demo.f_WE),
                                 height=built.scene.paper_height + 5e-4)  # fmt: skip
        recorder.stop_and_export(replay_path)
    times = np.array([row_t for row_t, _ in master.rows])
    rows = np.array([row for _, row in master.rows]).reshape(-1, len(COLUMNS))
    wall_times = np.asarray(holder["inputs"].wall_times) if live else source.wall_time
    log = InputsLog(time=times, wall_time=np.asarray(wall_times, float), rows=rows, end_time=t,
                    end_reason=reason if live else source.end_reason, seed=seed,
                    scenario=scenario.to_yaml())  # fmt: skip
    return Take(demo, log, built, master, page.updates if page else 0, wall)



def _takes_hint(folder):
    return f"hemg-drake teleop SCENARIO --out {folder.path} (or hemg-drake demonstrate)"


# Keys a take does not read (its length is the person's; the count is demonstrate's):
# scenarios that differ only there record compatible takes.
TAKE_FREE_KEYS = ("duration", "num_demonstrations")


def same_takes(yaml_a, yaml_b):
    """Whether two scenarios (YAML texts) record the same kind of take: equal but for
    :data:`TAKE_FREE_KEYS`."""
    from hemg_drake.scenario import parse_scenario

    def normal(text):
        scenario = parse_scenario(text, source="a dataset's scenario")
        return scenario.replaced(["duration=1.0", "num_demonstrations=1"]).to_yaml()

    return yaml_a == yaml_b or normal(yaml_a) == normal(yaml_b)


def existing_takes(scenario, out_dir):
    """The demonstrations already in ``out_dir/dataset.npz`` and its metadata, checked.

    Returns ``([], {})`` for a folder without a dataset. Raises ValueError if the dataset
    was not finished by a demonstrate/teleop stage, or holds another scenario's takes.
    """
    from hemg_drake.learning.demos import load_dataset
    from hemg_drake.run_folder import RunFolder

    folder = RunFolder(out_dir, create=True)
    if not folder.dataset.exists():
        return [], {}
    folder.check("demonstrate", folder.dataset, run_hint=_takes_hint(folder))
    demos, metadata = load_dataset(folder.dataset)
    if "scenario" not in metadata or not same_takes(metadata["scenario"], scenario.to_yaml()):
        raise ValueError(
            f"{folder.dataset}: holds demonstrations of another scenario (or other --set "
            "values); give a new --out folder for this one"
        )
    return demos, metadata


def teleop(scenario, out_dir, *, port=7000, duration=None, replay_inputs=None, replays=True,
           progress=print, meshcat=None, on_step=None, realtime=True):  # fmt: skip
    """Record one take from the browser (or re-drive one from its inputs log) and append it
    to ``out_dir/dataset.npz``, as :func:`hemg_drake.pipeline.demonstrate` writes it.

    The take's demonstration is appended to the dataset (its metadata names each one's
    operator), with ``replay_<c>.html`` (when ``replays``) and its raw inputs
    ``inputs_<c>.npz`` beside it, c its number in the dataset, and the figures redrawn; the
    folder's manifest records the demonstrate stage again, so ``learn`` and ``reproduce``
    take it; an older model and reproduction are removed (they no longer match). Takes
    already there are kept.

    Live (``replay_inputs`` None): without a ``meshcat``, one is started on ``port`` and
    the first line given to ``progress`` is ``Meshcat: http://localhost:P``. The take
    ends with the page's End take button or Escape, after ``duration`` simulated seconds,
    or when the page has been closed for 2 s, and is saved in each case. Ctrl-C
    (KeyboardInterrupt) discards it: nothing is written. With ``replay_inputs`` (a log
    path): headless, as fast as it runs, the same demonstration bit for bit (the log's
    seed; the scenario must be the log's).

    Returns
    -------
    list of Path, the files written (dataset first).
    """
    from hemg_drake.learning.demos import save_dataset
    from hemg_drake.pipeline import replay_recorder
    from hemg_drake.placements import (
        demonstration_scenario,
        describe_placement,
        has_placements,
        task_frames,
    )
    from hemg_drake.run_folder import RunFolder
    from hemg_drake.viz.figures import plot_demonstrations, plot_emg_envelopes, save_figure

    demos, metadata = existing_takes(scenario, out_dir)
    folder = RunFolder(out_dir, create=True)
    c = len(demos) + 1
    if replay_inputs is not None:
        source = load_inputs(replay_inputs)
        if not same_takes(source.scenario, scenario.to_yaml()):
            raise ValueError(
                f"{replay_inputs}: recorded with another scenario (or other --set values) "
                "than the one given"
            )
        seed, operator_name = source.seed, f"browser (replayed from {replay_inputs})"
    else:
        source, seed, operator_name = "meshcat", scenario.seed + c - 1, "browser"
        if meshcat is None:
            meshcat = start_meshcat(port)
            progress(f"Meshcat: http://localhost:{meshcat.port()}")
        keys = ", ".join(f"{name}: {down}/{up}" for name, (down, up) in KEYS.items())
        progress(
            f"take {c} into {folder.path}/: keys {keys}; gamepad sticks and right trigger; "
            f"End take or {END_KEY} ends it"
            + (f" (or {duration:g} s)" if duration is not None else "")
        )
    # With scene.placements each take happens at its own seed's placement, as a simulated
    # demonstration does (the same draw, so a re-driven log lands where it was recorded).
    here = demonstration_scenario(scenario, seed)
    if has_placements(scenario):
        progress(f"take {c}: {describe_placement(here)}")
    replay = folder / f"replay_{c}.html" if replays else None
    title = f"{scenario.task.replace('_', ' ')}: teleoperated take {c}"
    recorder = replay_recorder(here, title) if replays else None
    take = run_take(
        here, seed=seed, source=source, meshcat=meshcat, duration=duration,
        realtime=realtime and replay_inputs is None, recorder=recorder, replay_path=replay,
        progress=progress, on_step=on_step,
    )  # fmt: skip
    progress(
        f"take {c}: {take.inputs.end_time:.2f} s ({take.inputs.end_reason}), "
        f"{len(take.inputs.time)} input samples, in {take.wall_seconds:.1f} s of wall time"
    )
    inputs_path = folder / f"inputs_{c}.npz"
    new_files = [p for p in (replay, inputs_path) if p is not None]
    old_files = [
        folder / name
        for name in folder.manifest().get("demonstrate", {}).get("files", {})
        if name.startswith(("replay_", "inputs_")) and (folder / name).is_file()
    ]
    # The model and reproductions were made from the old dataset: remove them; the takes
    # already recorded stay (unlike a demonstrate stage, which starts the folder over).
    folder.begin("learn")
    try:
        save_inputs(inputs_path, take.inputs)
        demo = take.demonstration
        if not demos or demos[0].frame_A is not None:
            # Each demonstration carries the task frames where it was shown (an older
            # dataset without them keeps none).
            frame_A, frame_b = task_frames(here)
            demo = dc.replace(demo, frame_A=frame_A, frame_b=frame_b)
        demos = [*demos, demo]
        operators = metadata.get("operators", ["simulated"] * (len(demos) - 1))
        record = dict(
            # The dataset keeps the scenario it was begun with (takes differ only in length).
            scenario=metadata.get("scenario", scenario.to_yaml()), task=scenario.task,
            log_period=scenario.log_period, operators=[*operators, operator_name],
        )  # fmt: skip
        save_dataset(folder.dataset, demos, record)
    except BaseException:
        for path in new_files:
            path.unlink(missing_ok=True)
        raise
    figures = [folder / "demonstrations.png", folder / "fig6_emg.png"]
    save_figure(plot_demonstrations(demos, task=scenario.task), figures[0])
    save_figure(plot_emg_envelopes(demos[0].emg, per_channel=scenario.emg.per_channel), figures[1])
    written = [folder.dataset, *sorted(set(old_files) - set(new_files)), *new_files, *figures]
    folder.finish("demonstrate", written)
    return written


class HeadlessPage:
    """The live Meshcat page in headless Chromium, driven through the DevTools protocol.

    For tests, screenshots and latency checks without a person: ``press(code)`` sends a
    real key press to the page (as a keyboard would), ``screenshot()`` returns a PNG.
    Needs Debian's ``chromium`` and ``websocket-client`` (the dev extra). Use as a
    context manager; the browser process is ended on exit.

    Parameters
    ----------
    url : str, the page (``meshcat.web_url()``).
    size : (int, int), window size in pixels.
    timeout : float, seconds to wait for Chromium to start.
    """

    def __init__(self, url, *, size=(1280, 800), timeout=60.0):
        import select
        import tempfile

        import websocket


        chromium = find_chromium()
        if chromium is None:
            raise FileNotFoundError(
                "chromium not found on PATH: install it (apt-get install chromium)"
            )
        self._profile = tempfile.mkdtemp(prefix="hemg-teleop-chromium-")
        command = [
            chromium, *WEBGL_FLAGS, *QUIET_FLAGS,
            f"--user-data-dir={self._profile}", f"--window-size={size[0]},{size[1]}",
            "--remote-debugging-port=0", "--remote-allow-origins=*", url,
        ]  # fmt: skip
        # Its own process group: Chromium's helpers (GPU, crashpad) outlive the main process
        # and keep writing into the profile, so close() ends the whole group.
        self.process = subprocess.Popen(
            command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            text=True, start_new_session=True,
        )  # fmt: skip
        deadline = time.monotonic() + timeout
        browser_url = None
        try:
            while browser_url is None:
                left = deadline - time.monotonic()
                if left <= 0 or self.process.poll() is not None:
                    raise RuntimeError("headless Chromium did not start its DevTools endpoint")
                ready, _, _ = select.select([self.process.stderr], [], [], left)
                if ready:
                    line = self.process.stderr.readline()
                    if line.startswith("DevTools listening on "):
                        browser_url = line.split(" on ", 1)[1].strip()
            # The first page target is the one showing ``url``.
            self._ws = websocket.create_connection(browser_url, timeout=timeout)
            self._id = 0
            targets = self._call("Target.getTargets")["targetInfos"]
            page = next(t for t in targets if t["type"] == "page")
            session = self._call("Target.attachToTarget", targetId=page["targetId"], flatten=True)
            self._session = session["sessionId"]
        except BaseException:
            self.close()
            raise

    def _call(self, method, session=None, **params):
        import json

        self._id += 1
        message = {"id": self._id, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        self._ws.send(json.dumps(message))
        while True:
            reply = json.loads(self._ws.recv())
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"DevTools {method}: {reply['error']}")
                return reply.get("result", {})

    def page(self, method, **params):
        """Call a DevTools method on the page (e.g. ``Runtime.evaluate``)."""
        return self._call(method, session=self._session, **params)

    def press(self, code):
        """Press and release the key ``code`` (a KeyboardEvent.code, e.g. "ArrowRight")."""
        for kind in ("keyDown", "keyUp"):
            self.page("Input.dispatchKeyEvent", type=kind, code=code, key=code)

    def evaluate(self, expression):
        """The value of a javascript expression in the page."""
        result = self.page("Runtime.evaluate", expression=expression, returnByValue=True)
        return result.get("result", {}).get("value")

    def screenshot(self):
        """A PNG of the page (bytes)."""
        import base64

        return base64.b64decode(self.page("Page.captureScreenshot", format="png")["data"])

    def close(self):
        with contextlib.suppress(Exception):
            self._ws.close()
        self._signal_group(signal.SIGTERM)
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self._signal_group(signal.SIGKILL)  # helpers left behind
        with contextlib.suppress(Exception):
            self.process.stderr.close()
        remove_profile(self._profile)

    def _signal_group(self, signum):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.process.pid, signum)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
