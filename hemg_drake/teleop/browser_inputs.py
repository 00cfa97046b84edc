"""The browser master's input sources and their 100 Hz inputs log.

Each source gives one raw row (:data:`COLUMNS`) and the wall time of the reading per
``read(t)``, and changes nothing by it: the master keeps what it sampled in its Context, so
a source is a read-only handle that clones of the master may share:

- :class:`MeshcatInputs`: the live page. Keyboard through Meshcat sliders that the teleop
  page's keys move (:data:`KEYS`, :mod:`hemg_drake.teleop.browser_server`), limited to the Touch X's 160 x 120 x 120 mm workspace, and two keys for the
  muscle activation; a gamepad through ``Meshcat.GetGamepad()``; the "End take" button
  (Escape) and the number of open pages.
- :class:`LoggedInputs`: the same rows read back from an inputs log (:func:`save_inputs`),
  which re-drives the diagram headless to the same demonstration, bit for bit.

The keyboard sliders are not Drake's ``MeshcatPoseSliders``: checked (Drake 1.51), it names
its sliders ``{prefix}_x`` in metres (the log's columns and the page's labels are mm), has
no slider for the activation, raises "Meshcat already has a slider named stylus_x" for a
second take on the same page, and is read live by its pose port, whereas a take samples the
sliders once per 10 ms into the log that re-drives it.
"""

import dataclasses as dc
import math
import time

import numpy as np

from hemg_drake._validate import as_vector
from hemg_drake.fileio import load_npz, save_npz_atomic
from hemg_drake.teleop.master import TOUCH_X_WORKSPACE

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
# The shared control's switch (docs/shared_control.md): each click toggles the assist between
# the scenario's mode and none (on at the take's start).
ASSIST_BUTTON, ASSIST_KEY = "Assist on/off", "KeyA"
# The keys move the stylus target through the page's script (browser_server): a tap moves
# it TAP_MM, a key held longer than HOLD_DELAY (s) moves it at HOLD_MM_S in wall-clock time;
# with Shift, FINE of both. At the tool that is the workspace map's scale (2) times as much.
TAP_MM, HOLD_MM_S, HOLD_DELAY, FINE = 0.5, 10.0, 0.25, 0.25
# The activation: a tap of X / Z, and its speed while held (per s).
ACTIVATION_TAP, ACTIVATION_HOLD_S = 0.05, 1.0
# The sliders' resolution (mm; activation: 1).
SLIDER_STEP_MM, ACTIVATION_STEP = 0.01, 0.01
# The fastest the keyboard's target moves (m/s, at the stylus), sample by sample: above any
# held key's speed, so a stall of the simulation never turns into a jump.
KEY_SPEED = 0.025

# Columns of one raw input row, as logged.
N_AXES, N_BUTTONS = 4, 17  # the W3C standard gamepad mapping
TRIGGER_BUTTON = 7
# The left bumper held: the sticks at FINE of their speed (fine motion, as Shift).
FINE_BUTTON = 4
COLUMNS = (
    "slider_x_mm", "slider_y_mm", "slider_z_mm", "slider_activation", "gamepad_index",
    *(f"axis_{i}" for i in range(N_AXES)), *(f"button_{i}" for i in range(N_BUTTONS)),
    "end_clicks", "connections", "assist_clicks",
)  # fmt: skip
# The columns of logs written before the assist's switch (read with assist_clicks 0).
COLUMNS_BEFORE_ASSIST = COLUMNS[:-1]
COLUMN_INDEX = {name: i for i, name in enumerate(COLUMNS)}
INPUTS_FORMAT = 1


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
    assist : bool
        Add the assist's switch (:data:`ASSIST_BUTTON`, A) and read its clicks (else 0).
    clock : callable
        Wall clock (s) logged with every row (``time.monotonic``).
    """

    def __init__(self, meshcat, *, p_MS_initial, workspace_size=TOUCH_X_WORKSPACE,
                 activation=0.05, assist=False, clock=time.monotonic):  # fmt: skip
        self.meshcat = meshcat
        self.assist = bool(assist)
        self.clock = clock
        half_mm = 500.0 * as_vector("workspace_size", workspace_size, 3)
        start_mm = 1000.0 * as_vector("p_MS_initial", p_MS_initial, 3)
        existing = set(meshcat.GetSliderNames())
        sliders = [(name, -h, h, SLIDER_STEP_MM, p)
                   for name, h, p in zip((SLIDER_X, SLIDER_Y, SLIDER_Z), half_mm, start_mm)]
        sliders.append((SLIDER_ACTIVATION, 0.0, 1.0, ACTIVATION_STEP, activation))
        for name, low, high, step, value in sliders:
            if name in existing:  # a second take on the same page: back to the start
                meshcat.SetSliderValue(name, value)
            else:  # the page's script moves them (KEYS): no Meshcat key bindings
                meshcat.AddSlider(name, low, high, step, value)
        meshcat.AddButton(END_BUTTON, keycode=END_KEY)  # (again: resets its clicks)
        if self.assist:
            meshcat.AddButton(ASSIST_BUTTON, keycode=ASSIST_KEY)

    def read(self, t):
        """The page's inputs now: (row of len(COLUMNS) floats, wall time in s)."""
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
        row.append(float(m.GetButtonClicks(ASSIST_BUTTON)) if self.assist else 0.0)
        return row, float(self.clock())


class LoggedInputs:
    """An input source reading back a log's rows: the row logged at exactly the time asked.

    Parameters
    ----------
    times : array, shape (N,), s, increasing
    rows : array, shape (N, len(COLUMNS))
    wall_times : array, shape (N,), s, optional
        Returned with each row (NaN without).
    """

    def __init__(self, times, rows, wall_times=None):
        self.times = np.asarray(times, dtype=float)
        self.rows = np.asarray(rows, dtype=float)
        self.wall_times = (np.full(self.times.shape, math.nan) if wall_times is None
                           else np.asarray(wall_times, dtype=float))  # fmt: skip
        if self.rows.ndim != 2 or self.rows.shape[1] != len(COLUMNS):
            raise ValueError(
                f"input rows must have shape (N, {len(COLUMNS)}), got {self.rows.shape}"
            )
        if self.times.shape != (len(self.rows),) or self.wall_times.shape != self.times.shape:
            raise ValueError("input times and wall times must have one entry per row")
        if np.any(np.diff(self.times) <= 0):
            raise ValueError("input times must increase")

    def read(self, t):
        """The row logged at time ``t`` (s) and its wall time; ValueError if there is none."""
        k = int(np.searchsorted(self.times, t))
        if k >= len(self.rows):
            end = f"t = {self.times[-1]:.3f} s" if len(self.times) else "no sample"
            raise ValueError(
                f"the inputs log ends at {end} but the diagram asks for t = {t:.3f} s: the "
                "log does not belong to this take"
            )
        if self.times[k] != t:
            raise ValueError(
                f"the inputs log has no sample at t = {t!r} s (the next is at "
                f"t = {float(self.times[k])!r} s): recorded with another input period or "
                "scenario"
            )
        return self.rows[k].tolist(), float(self.wall_times[k])


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
    columns, rows = tuple(str(c) for c in arrays["columns"]), arrays["rows"]
    if columns == COLUMNS_BEFORE_ASSIST:  # an older log: the assist was never switched
        rows = np.column_stack([rows, np.zeros(len(rows))])
    elif columns != COLUMNS:
        raise ValueError(f"{path}: the inputs log's columns differ from this version's")
    return InputsLog(
        time=arrays["time"], wall_time=arrays["wall_time"], rows=rows,
        end_time=float(arrays["end_time"]), end_reason=str(arrays["end_reason"]),
        seed=int(arrays["seed"]), scenario=str(arrays["scenario"]),
    )  # fmt: skip
