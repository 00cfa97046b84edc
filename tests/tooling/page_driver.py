"""A closed-loop key driver for the teleop page: it reads what the page shows (the Meshcat
scene tree's tool, target, pin and template strokes; the overlay's state line and read-outs)
and presses keys as a person would, counting every press. Test tooling shared by
tests/teleop/test_teleop_person.py and benchmarks; not runtime.

Nothing here knows the workspace map: the keys' directions at the tool are measured on the
page (one tap each, the stylus target's motion seen in the scene).
"""

import collections
import re
import time

import numpy as np

from tooling.teleop_page import state

TARGET = ["teleop", "target"]
HAND = ["drake", "illustration", "baxter_right_arm", "right_hand"]
PIN = ["drake", "illustration", "cotter_pin", "pin"]
# The keys that move the tool, by the master axis they move (+ key, - key).
AXIS_KEYS = {"x": ("ArrowRight", "ArrowLeft"), "y": ("KeyW", "KeyS"), "z": ("ArrowDown", "ArrowUp")}
# The activation read-out a relaxed operator returns to (the slider starts at 0.05).
RELAXED = 0.1


class PageDriver:
    """Key presses on a :class:`~tooling.headless_page.HeadlessPage` and what the page shows.

    ``presses`` counts the presses by key (a tap is one press: keyDown then keyUp).
    """

    def __init__(self, page):
        self.page = page
        self.presses = collections.Counter()
        self.directions = {}

    # -- what the page shows --------------------------------------------------------------
    def position(self, path):
        """A scene node's position in the world (m, Drake's W: the node's own transform, as
        set by Meshcat's SetTransform or the page's echo of the keys). Its ``position``, not
        its ``matrix``: three.js recomputes the matrix from it only when it renders, so on a
        page that has not rendered since a tap the matrix still shows the cross before it."""
        js = ("(function(){const p = viewer.scene_tree.find(%s).object.position;"
              " return [p.x, p.y, p.z];})()" % list(path))
        return np.array(self.page.evaluate(js), dtype=float)

    def template(self):
        """The template strokes the page shows: a list of (k, 3) arrays (m, W)."""
        js = ("(function(){const t = viewer.scene_tree.find(['teleop', 'template']); "
              "return Object.keys(t.children).sort().map(k => {let o = t.children[k].object;"
              " while (o && !o.geometry) o = o.children[0];"
              " return Array.from(o.geometry.attributes.position.array);});})()")
        return [np.array(s, dtype=float).reshape(-1, 3) for s in self.page.evaluate(js)]

    def ink_strokes(self):
        """How many strokes of ink the page shows."""
        js = ("(function(){const t = viewer.scene_tree.find(['teleop', 'ink']); "
              "return Object.keys(t.children).length;})()")
        return int(self.page.evaluate(js) or 0)

    def text(self, element):
        return self.page.evaluate(f"document.getElementById('{element}').textContent") or ""

    def number(self, element):
        """The first number in an overlay read-out (hemg-a: activation, hemg-f: force, hemg-w:
        the assist's weight)."""
        match = re.search(r"-?\d+(\.\d+)?", self.text(element))
        return float(match.group()) if match else float("nan")

    def take_time(self):
        """The take's time on the state line ("take 1: recording 3.2 s"), s; NaN if none."""
        match = re.search(r"recording (\d+(\.\d+)?) s", state(self.page))
        return float(match.group(1)) if match else float("nan")

    def wait_take_time(self, dt, timeout=300.0):
        """Wait until the take's (simulated) time has advanced by ``dt`` s."""
        deadline = time.monotonic() + timeout
        start = self.take_time()
        while start != start:  # NaN: the state line missed a poll (a loaded machine)
            if time.monotonic() > deadline:
                raise TimeoutError(f"the page shows no take time: {state(self.page)!r}")
            time.sleep(0.05)
            start = self.take_time()
        while not self.take_time() >= start + dt - 1e-9:
            if time.monotonic() > deadline:
                raise TimeoutError(f"the take's time stayed at {start} s: {state(self.page)!r}")
            time.sleep(0.02)

    # -- pressing -------------------------------------------------------------------------
    def tap(self, code, *, shift=False):
        self.page.press(code, shift=shift)
        self.presses[code] += 1

    def settled_target(self, dt=0.15):
        """The target once it has stopped moving (two reads ``dt`` of take time apart)."""
        before = self.position(TARGET)
        while True:
            self.wait_take_time(dt)
            now = self.position(TARGET)
            if np.linalg.norm(now - before) < 1e-5:
                return now
            before = now

    def calibrate(self, axes="xyz"):
        """Measure each axis' + key's motion of the target at the tool (m per tap, W) with a
        tap there and back; sets ``directions`` (one W vector per axis)."""
        for axis in axes:
            plus, minus = AXIS_KEYS[axis]
            start = self.settled_target()
            self.tap(plus)
            moved = self.settled_target()
            self.tap(minus)
            back = self.settled_target()
            d = moved - start
            if np.linalg.norm(d) < 1e-4:  # the target was at the workspace's wall: the other way
                self.tap(minus)
                d = back - self.settled_target()
                self.tap(plus)
                self.settled_target()
            if np.linalg.norm(d) < 1e-4:
                raise RuntimeError(f"the keys {plus} / {minus} move nothing on the page")
            self.directions[axis] = d
        return self.directions

    def step_towards(self, goal, *, tolerance, axes="xz", fine_below=None):
        """One tap on the axis (of ``axes``) whose key moves the target most towards ``goal``
        (m, W); False when the target is within ``tolerance`` of it along every axis."""
        target = self.position(TARGET)
        best, gain = None, 0.0
        for axis in axes:
            d = self.directions[axis]
            step = float(np.dot(goal - target, d) / np.dot(d, d))  # in taps
            if abs(step) * np.linalg.norm(d) > tolerance and abs(step) > abs(gain):
                best, gain = axis, step
        if best is None:
            return False
        fine = fine_below is not None and abs(gain) * np.linalg.norm(self.directions[best]) < fine_below
        self.tap(AXIS_KEYS[best][0 if gain > 0 else 1], shift=fine)
        return True


def hold_towards(driver, goal, *, near, axes="xz", slack=1e-3, fine_slant=None, timeout=120.0):
    """Hold the keys that move the target towards ``goal`` (m, W) along the straight line
    from where it is, as a person draws a slanted line with the arrows, watching the cross
    (the page echoes the keys at once): the key of the axis with the longer way is held
    until the cross is within ``near`` (m) of the goal along it (or past it); the other
    axis' key is held while the cross lags the line by more than ``slack`` (m) along that
    axis, and let go once it is back on it. Each press of that key moves one tap, then
    nothing for the page's hold delay (0.25 s), so near 45 degrees the cross can lag the
    line by a few millimetres before it catches up. With ``fine_slant``, a line more slanted
    than that (its shorter way over its longer) is held with Shift, a quarter of the speed,
    as a person slows down for a slant: the cross then leaves the line by a quarter as much
    (at full speed the zig-zag's legs came out as staircases 3-8 mm off their lines). Then
    the target settles; taps (:meth:`PageDriver.step_towards`) do the rest."""
    start = driver.position(TARGET)
    units = {a: driver.directions[a] / np.linalg.norm(driver.directions[a]) for a in axes}
    way = {a: float(np.dot(goal - start, u)) for a, u in units.items()}  # m, signed
    major = max(axes, key=lambda a: abs(way[a]))
    if abs(way[major]) <= near:
        return
    minor = max((abs(way[a]) for a in axes if a != major), default=0.0)
    fine = fine_slant is not None and minor > fine_slant * abs(way[major])
    held = {}  # axis -> the key held
    deadline = time.monotonic() + timeout

    def hold(axis, key):
        if held.get(axis) != key:
            release(axis)
            driver.page.key("keyDown", key, shift=fine)
            driver.presses[key] += 1
            held[axis] = key

    def release(axis):
        if axis in held:
            driver.page.key("keyUp", held.pop(axis), shift=fine)

    try:
        while True:
            moved = driver.position(TARGET) - start
            left = way[major] - float(np.dot(moved, units[major]))
            if abs(left) <= near or left * way[major] < 0:  # there, or past it
                break
            hold(major, AXIS_KEYS[major][0 if way[major] > 0 else 1])
            done = 1.0 - left / way[major]  # the fraction of the line behind the cross
            for axis in axes:
                if axis == major:
                    continue
                lag = done * way[axis] - float(np.dot(moved, units[axis]))  # m, signed
                if abs(lag) > slack:
                    hold(axis, AXIS_KEYS[axis][0 if lag > 0 else 1])
                elif lag * {AXIS_KEYS[axis][0]: 1, AXIS_KEYS[axis][1]: -1}.get(held.get(axis), 0) <= 0:
                    release(axis)  # on the line (or its key would take it past)
            if time.monotonic() > deadline:
                raise TimeoutError(f"holding {sorted(held.values())}: the cross stays at {moved + start}")
            time.sleep(0.02)
    finally:
        for key in held.values():
            driver.page.key("keyUp", key, shift=fine)
    driver.settled_target()


def pull_pin(driver, *, pin_length, activation=0.6, dt=0.1, timeout=600.0):
    """Squeeze, then pull the pin until the page shows it out; closed loop, by taps.

    Each ``dt`` of take time: while the activation read-out is below ``activation`` tap X;
    then tap W whenever the hand rose less than 0.5 mm in the last ``dt`` (a person taps
    again when the tool stops; an assist that pulls saves the taps). Returns the pin's
    withdrawal seen (m).
    """
    start = driver.position(PIN)
    hand = driver.position(HAND)
    deadline = time.monotonic() + timeout
    while True:
        out = float(driver.position(PIN)[2] - start[2])
        if out >= pin_length:
            return out
        if time.monotonic() > deadline:
            raise TimeoutError(f"the pin is only {1e3 * out:.1f} mm out; {dict(driver.presses)}")
        if driver.number("hemg-a") < activation:
            driver.tap("KeyX")
        else:
            now = driver.position(HAND)
            if now[2] - hand[2] < 5e-4:
                driver.tap("KeyW")
            hand = now
        driver.wait_take_time(dt)


def draw_strokes(driver, *, depth=2.5e-3, contact=0.5, tolerance=1.5e-3, dt=0.04,
                 lift=6e-3, hold=None, activation=None, timeout=1800.0):
    """Draw the template strokes the page shows, closed loop, by taps (and held keys: with
    ``hold`` (m) each move is held to within ``hold`` of its waypoint, :func:`hold_towards`;
    with ``activation``, tensed (X) to that read-out before each pen-down and relaxed (Z) to
    ``RELAXED`` after each lift, as the paper's operator stiffens the arm to draw).

    The keys' directions are measured first (:meth:`PageDriver.calibrate`). For each stroke:
    move the target above its start (the arrows), lower the pen (S) until the force read-out
    shows contact (> ``contact`` N), then ``depth`` (m) further into the paper, follow the
    stroke's waypoints to within ``tolerance`` (m; Shift for the last millimetre), and lift
    (W) until the force is gone and ``lift`` more. One decision per ``dt`` of take time.
    Returns the number of ink strokes the page shows.
    """
    deadline = time.monotonic() + timeout
    directions = driver.calibrate("xyz")
    up = directions["y"]  # W moves the target up
    tap_up = float(np.linalg.norm(up))

    def check():
        if time.monotonic() > deadline:
            raise TimeoutError(f"drawing: out of time; presses {dict(driver.presses)}")

    def press(key, touching, further):
        """Tap ``key`` until the force read-out says touching (or not), then ``further`` (m)."""
        while (driver.number("hemg-f") > contact) != touching:
            driver.tap(key)
            driver.wait_take_time(2 * dt)
            check()
        for _ in range(max(1, round(further / tap_up))):
            driver.tap(key)
            driver.wait_take_time(dt)

    def tense(above, key, level):
        """Tap ``key`` until the activation read-out is above (or below) ``level``."""
        while (driver.number("hemg-a") >= level) != above:
            driver.tap(key)
            driver.wait_take_time(dt)
            check()

    for stroke in driver.template():
        for k, point in enumerate(stroke):
            if hold is not None:  # the long way held (slants slowly), the last mm tapped
                hold_towards(driver, point, near=hold, fine_slant=0.1 if k > 0 else None)
            while driver.step_towards(point, tolerance=tolerance, fine_below=2 * tolerance):
                driver.wait_take_time(dt)
                check()
            if k == 0:
                if activation is not None:
                    tense(True, "KeyX", activation)
                press("KeyS", True, depth)  # pen down: to contact, then depth further
        press("KeyW", False, lift)  # pen up: off the paper, then lift higher
        if activation is not None:
            tense(False, "KeyZ", RELAXED)
    driver.wait_take_time(0.3)
    return driver.ink_strokes()
