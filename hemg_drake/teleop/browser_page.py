"""The teleop page on Meshcat: what the hand cannot feel (:class:`TeleopPage`), the operator's
view (:func:`operator_view`) and the person's hold on a take (:class:`TakeControls`). The
Meshcat server a take is driven from is a loopback ``Visualization``
(:mod:`hemg_drake.diagrams.visualization`); the page a person opens is served by
:mod:`hemg_drake.teleop.browser_server`."""

import math
import time

import numpy as np
from pydrake.geometry import Box, Cylinder, MeshcatCone, Rgba, Sphere
from pydrake.math import RigidTransform, RotationMatrix

from hemg_drake.teleop.browser_server import SLOW_RATE

MAX_SHOWN_FORCE = 60.0


def operator_view(points_W, master_to_slave, *, elevation_deg=30.0, margin=2.5):
    """The operator's view of the task: (camera_in_world, target_in_world), m.

    The camera looks at the middle of ``points_W`` (the task's plan points) from the
    operator's side, tilted down by ``elevation_deg``: along the master's -z (away from the
    operator), with the master's x to the right on screen and its y up, so that the keys'
    directions (right, up, away) are the screen's. ``master_to_slave`` maps a master point
    to W (the workspace map); the distance frames the task's extent (``margin`` times it,
    at least 0.3 m).
    """
    points = np.asarray(points_W, dtype=float)
    centre = (points.min(axis=0) + points.max(axis=0)) / 2
    origin = np.asarray(master_to_slave(np.zeros(3)), dtype=float)
    towards = np.asarray(master_to_slave(np.array([0.0, 0.0, 1.0])), dtype=float) - origin
    up = np.asarray(master_to_slave(np.array([0.0, 1.0, 0.0])), dtype=float) - origin
    towards, up = towards / np.linalg.norm(towards), up / np.linalg.norm(up)
    extent = float(np.max(points.max(axis=0) - points.min(axis=0)))
    distance = max(0.45, margin * extent)
    e = math.radians(elevation_deg)
    camera = centre + distance * (math.cos(e) * towards + math.sin(e) * up)
    return camera, centre


class TeleopPage:
    """What the hand cannot feel, on the Meshcat page and the teleop page's read-outs: the
    force the tool applies (-f_WE) as an arrow beside the tool (6 cm to the operator's
    right, ``right_W``; 1 cm per newton) and a bar, K
    and the activation as bars, the take's state and time, and the stylus target (a blue
    cross and sphere, mapped to the slave's side, larger than the tool so it shows).

    ``server`` (a :class:`~hemg_drake.teleop.browser_server.TeleopPageServer`) gets the
    read-outs; without one only the scene marks are drawn.
    """

    PATH = "/teleop"
    ARROW_SCALE = 0.01  # m per N

    def __init__(self, meshcat, *, k_min, k_max, server=None, take=None, right_W=(0, -1, 0),
                 echo_map=None):  # fmt: skip
        self.meshcat = meshcat
        # The arrow starts beside the tool, to the operator's right, not inside the arm.
        self.arrow_offset = 0.06 * np.asarray(right_W, dtype=float)
        self.server = server
        self.take = take
        self.k_min, self.k_max = float(k_min), float(k_max)
        orange = Rgba(1.0, 0.5, 0.0, 1.0)
        # The arrow points along its frame's +z; the shaft (1 m, scaled) and the head are
        # separate paths so scaling the shaft does not stretch the head.
        meshcat.SetObject(f"{self.PATH}/force/shaft/geometry", Cylinder(0.004, 1.0), orange)
        meshcat.SetTransform(f"{self.PATH}/force/shaft/geometry", RigidTransform([0, 0, 0.5]))
        meshcat.SetObject(f"{self.PATH}/force/head", MeshcatCone(0.02, 0.01, 0.01), orange)
        blue = Rgba(0.0, 0.6, 1.0, 0.9)
        meshcat.SetObject(f"{self.PATH}/target/ball", Sphere(0.007), blue)
        for axis, size in (("x", [0.06, 0.003, 0.003]), ("y", [0.003, 0.06, 0.003]),
                           ("z", [0.003, 0.003, 0.06])):  # fmt: skip
            meshcat.SetObject(f"{self.PATH}/target/{axis}", Box(*size), blue)
        # The page's local echo (browser_server): the cross moves with the page's own
        # sliders at once, from the newest command (update's p_WC) by ``echo_map`` (3 x 3,
        # m in W per m of the stylus: the workspace map's linear part), the target's
        # userData [p_WC (3), sliders (3, mm), echo_map (9, row-major)].
        # (Meshcat's set_property sets only properties that exist: the whole userData.)
        meshcat.SetProperty(f"{self.PATH}/target", "userData", [])
        self._echo_map = (None if echo_map is None
                          else np.asarray(echo_map, dtype=float).reshape(9).tolist())  # fmt: skip
        self._echo = self._target = self._force_visible = None
        meshcat.SetProperty(f"{self.PATH}/force", "visible", False)
        meshcat.SetProperty("/Axes", "visible", False)  # the world axes hide the arm's base
        self.updates = 0
        # Live ink (draw_ink): the strokes so far and the points of the piece being drawn.
        self.ink_height = self.ink_threshold = None
        self._stroke, self._piece, self._points, self._touching = 0, 0, [], False
        if server is not None:
            server.update(K=self.k_min, K_min=self.k_min, K_max=self.k_max,
                          force_max=MAX_SHOWN_FORCE)  # fmt: skip

    INK_PIECE = 50  # points per Meshcat line of live ink (each update re-sends one piece)

    def draw_ink(self, height, threshold):
        """Draw ink on the sheet live, where the tool touches it (|f_WE| > ``threshold``, N),
        at ``height`` (m, just above the paper)."""
        self.ink_height, self.ink_threshold = float(height), float(threshold)
        self.meshcat.Delete(f"{self.PATH}/ink")

    def show_template(self, strokes, height):
        """The demonstrated strokes, faint, at ``height`` (m): a list of (k, 3) polylines."""
        self.meshcat.Delete(f"{self.PATH}/template")
        for i, stroke in enumerate(strokes):
            points = np.array(stroke, dtype=float)
            points[:, 2] = height
            self.meshcat.SetLine(f"{self.PATH}/template/{i}", np.asfortranarray(points.T), 6.0,
                                 Rgba(0.55, 0.55, 0.6, 0.5))  # fmt: skip

    def _ink(self, p_WE, f_WE):
        touching = float(np.linalg.norm(f_WE)) > self.ink_threshold
        if not touching:
            if self._touching:
                self._stroke, self._piece, self._points = self._stroke + 1, 0, []
            self._touching = False
            return
        self._touching = True
        self._points.append([p_WE[0], p_WE[1], self.ink_height])
        if len(self._points) >= 2:
            path = f"{self.PATH}/ink/{self._stroke}/{self._piece}"
            self.meshcat.SetLine(path, np.asfortranarray(np.array(self._points).T), 3.0,
                                 Rgba(0.05, 0.45, 0.15, 1.0))  # fmt: skip
        if len(self._points) >= self.INK_PIECE:  # the next piece starts where this ends
            self._piece, self._points = self._piece + 1, self._points[-1:]

    def state(self, state, t=0.0, hint=None):
        """The state line: "waiting", "recording", "ended", "saved" (or a not-kept reason)."""
        if self.server is None:
            return
        c = f"take {self.take}" if self.take is not None else "take"
        headline, default = {
            "waiting": (f"{c}: waiting", "press Enter (or Start take) to start"),
            "recording": (f"{c}: recording {t:.1f} s", "Esc (or End take) ends it"),
            "ended": (f"{c}: ended at {t:.1f} s", "K keeps it, D discards it"),
            "saved": (f"{c}: saved", "the next take is being prepared"),
        }.get(state, (f"{c}: {state}", ""))
        if state == "waiting" and self.server.shown("state") in ("saved", "not kept"):
            # How the last take ended stays on the line: the next one may be ready sooner
            # than the page polls (a person, or a test, would miss "discarded").
            headline += f" (last: {self.server.shown('headline')})"
        self.server.update(state=state, headline=headline, hint=default if hint is None else hint)

    def update(self, t, p_WE, f_WE, gain, recording, p_WT=None, activation=None, rate=None,
               echo=None, assist=None):  # fmt: skip
        """Refresh the marks and read-outs; ``echo`` = (p_WC, sliders): where the newest
        sample sends the target (m, in W) and its sliders (mm), for the page's local echo
        (:meth:`BrowserMaster.command <hemg_drake.teleop.browser.BrowserMaster_.command>`);
        ``assist`` (a dict: weight, phase, states, belief, confidence, on, link_lost) the
        shared control's read-outs."""
        m = self.meshcat
        f = -np.asarray(f_WE, dtype=float)  # the force the tool applies to the task
        magnitude = float(np.linalg.norm(f))
        length = self.ARROW_SCALE * magnitude
        visible = length > 1e-3
        if visible != self._force_visible:  # unchanged: nothing to send (nor to render)
            m.SetProperty(f"{self.PATH}/force", "visible", visible)
            self._force_visible = visible
        if visible:
            p_WE = np.asarray(p_WE, dtype=float) + self.arrow_offset
            R = _rotation_z_to(f / magnitude)
            # The cone's apex is at its frame's origin and it opens along +z: turn it over.
            head = RigidTransform(R, p_WE) @ RigidTransform(
                RotationMatrix.MakeXRotation(math.pi), [0, 0, length + 0.02]
            )
            m.SetTransform(f"{self.PATH}/force/shaft", RigidTransform(R, p_WE))
            m.SetProperty(f"{self.PATH}/force/shaft", "scale", [1.0, 1.0, length])
            m.SetTransform(f"{self.PATH}/force/head", head)
        if echo is not None and self._echo_map is not None:
            values = [*np.asarray(echo[0], dtype=float).tolist(), *map(float, echo[1]),
                      *self._echo_map]  # fmt: skip
            if values != self._echo:  # sent before the transform: both reach the same frame
                m.SetProperty(f"{self.PATH}/target", "userData", values)
                self._echo = values
        if p_WT is not None and list(map(float, p_WT)) != self._target:
            self._target = list(map(float, p_WT))
            m.SetTransform(f"{self.PATH}/target", RigidTransform(np.asarray(p_WT, float)))
        if self.ink_height is not None and recording:
            self._ink(np.asarray(p_WE, dtype=float), f_WE)
        if self.server is not None:
            values = dict(K=float(gain), force=min(magnitude, MAX_SHOWN_FORCE))
            if activation is not None:
                values["activation"] = float(activation)
            if assist is not None:
                values["assist"] = dict(assist)
            # The page paces its software rendering on it (browser_server.OVERLAY's pace).
            values["rate"] = None if rate is None else round(float(rate), 3)
            if rate is not None:
                values["slow"] = (
                    f"the simulation runs at {rate:.2f}x real time: motion is slowed"
                    if rate < SLOW_RATE else ""
                )  # fmt: skip
            self.server.update(**values)
            if recording:
                self.state("recording", t)
        self.updates += 1


def _rotation_z_to(direction):
    """A rotation taking +z to the unit vector ``direction``."""
    z = np.asarray(direction, dtype=float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return RotationMatrix(np.column_stack([x, y, z]))



# The take's buttons besides End take (browser_inputs.END_BUTTON, Escape) and their keys.
START_BUTTON, KEEP_BUTTON, DISCARD_BUTTON = "Start take", "Keep take", "Discard take"
START_KEY, KEEP_KEY, DISCARD_KEY = "Enter", "KeyK", "KeyD"
# Wall-clock seconds without a page, after one was open, that count as the page closed.
CLOSED_PAGE_SECONDS = 2.0


class TakeControls:
    """The person's hold on a take: Start take (Enter) before it, Keep take (K) or Discard
    take (D) after it. A take never starts by itself, and is saved only when kept.

    Waiting happens in wall time, before the take's simulator starts (or after it ended);
    ``poll`` (seconds) is how often the buttons are read. ``on_wait`` is called with the
    seconds waited so far at each poll (the page's state line).
    """

    def __init__(self, meshcat, *, poll=0.02, clock=time.monotonic, sleep=time.sleep):
        self.meshcat = meshcat
        self.poll, self.clock, self.sleep = poll, clock, sleep
        existing = set(meshcat.GetButtonNames())
        for name, key in ((START_BUTTON, START_KEY), (KEEP_BUTTON, KEEP_KEY),
                          (DISCARD_BUTTON, DISCARD_KEY)):  # fmt: skip
            if name not in existing:
                meshcat.AddButton(name, keycode=key)
        # Clicks counted from a mark, by button. The first Start counts from the button's
        # creation: a person who presses Enter while the scene is still being built (the
        # button is on the page already) has started the take.
        self._marked = {START_BUTTON: meshcat.GetButtonClicks(START_BUTTON)}

    def _wait(self, names, on_wait, opened):
        """The first of ``names`` clicked from now on, or None once the page was closed for
        CLOSED_PAGE_SECONDS (after being open: ``opened`` says whether it was)."""
        m = self.meshcat
        base = {name: self._marked.get(name, m.GetButtonClicks(name)) for name in names}
        self._marked = {}
        began = last_open = self.clock()
        while True:
            for name in names:
                if m.GetButtonClicks(name) > base[name]:
                    return name
            now = self.clock()
            if m.GetNumActiveConnections() > 0:
                opened, last_open = True, now
            elif opened and now - last_open >= CLOSED_PAGE_SECONDS:
                return None
            if on_wait is not None:
                on_wait(now - began)
            self.sleep(self.poll)

    def mark(self, *names):
        """Count the clicks of ``names`` from now on (call it when the page starts asking,
        before the state line says so: a click the page asked for is never missed)."""
        self._marked = {name: self.meshcat.GetButtonClicks(name) for name in names}

    def mark_start(self):
        if START_BUTTON not in self._marked:  # the first take's mark stands (__init__)
            self.mark(START_BUTTON)

    def mark_keep(self):
        self.mark(KEEP_BUTTON, DISCARD_BUTTON)

    def wait_start(self, on_wait=None, *, opened=False):
        """Block until Start take is clicked (True) or the page was closed (False)."""
        return self._wait([START_BUTTON], on_wait, opened) is not None

    def ask_keep(self, on_wait=None):
        """Block until Keep take (True) or Discard take (False) is clicked; a closed page
        discards (False)."""
        return self._wait([KEEP_BUTTON, DISCARD_BUTTON], on_wait, True) == KEEP_BUTTON
