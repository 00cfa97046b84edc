"""Teleoperating from the browser: speed, publishing rate and input latency (issue 17).

Speed: one take of each task with the whole live setup (the demonstration diagram with a
BrowserMaster, the arm in Meshcat, the page's force arrow, bar and read-outs refreshed at
32 Hz, the replay recorder), simulated as fast as it goes (no real-time pacing) while a
websocket client, standing in for the page, receives everything Meshcat publishes. Prints
the real-time factor (must be >= 1 for a person to drive it at real time) and the rate of
scene updates the client received per simulated second.

Latency: a take at real time (``set_target_realtime_rate(1)``) while another thread sends
gamepad messages on Meshcat's websocket, as the page does, at irregular wall times; for
each deflection of the left stick it prints the wall time until the BrowserMaster sampled
it and until the stylus had moved 0.05 mm (the demonstration log's 10 ms resolution).

``--chromium``: the speed again with the page open in headless Chromium on the same
cores (software WebGL, the worst case for a browser on this machine), and the latency
from a key press in that page (DevTools) to the BrowserMaster's sample of the slider.

``--screenshot PNG``: a picture of the live page (headless Chromium) mid-take, with the
controls open and the arm pulling the pin, e.g. docs/img/teleop_page.png.

    .venv/bin/python benchmarks/bench_teleop_browser.py [--seconds 6] [--chromium]
    .venv/bin/python benchmarks/bench_teleop_browser.py --screenshot docs/img/teleop_page.png
"""

import argparse
import contextlib
import math
import sys
import tempfile
import threading
import time
from pathlib import Path

import msgpack
import numpy as np
import websocket

from hemg_drake.diagrams.visualization import Visualization
from hemg_drake.fileio import write_bytes_atomic
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.teleop.browser_inputs import COLUMNS
from hemg_drake.teleop_session import run_take

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from tooling.headless_page import HeadlessPage  # noqa: E402  (test tooling, not runtime)


class Listener:
    """A websocket client counting the scene updates Meshcat sends it."""

    def __init__(self, meshcat):
        self.ws = websocket.create_connection(meshcat.ws_url(), timeout=5)
        self.transforms = {}  # path -> set_transform messages received
        self.stop = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        self.ws.settimeout(0.2)
        while not self.stop:
            try:
                message = self.ws.recv()
            except websocket.WebSocketTimeoutException:
                continue
            except (websocket.WebSocketException, OSError):
                return
            if isinstance(message, bytes):
                try:
                    decoded = msgpack.unpackb(message, raw=False, strict_map_key=False)
                except Exception:
                    continue
                if isinstance(decoded, dict) and decoded.get("type") == "set_transform":
                    path = decoded.get("path")
                    self.transforms[path] = self.transforms.get(path, 0) + 1

    def send(self, **message):
        self.ws.send_binary(msgpack.packb(message))

    def close(self):
        self.stop = True
        self.thread.join(timeout=2)
        self.ws.close()


def speed(task, seconds, chromium=False):
    scenario = load_scenario(shipped_scenario(task))
    visualization = Visualization(0)
    meshcat = visualization.meshcat
    listener = Listener(meshcat)
    # The page itself rendering on the same 2 cores (software WebGL: the worst case).
    page = HeadlessPage(meshcat.web_url()) if chromium else contextlib.nullcontext()
    deadline = time.monotonic() + 60
    while chromium and meshcat.GetNumActiveConnections() < 2 and time.monotonic() < deadline:
        time.sleep(0.05)  # the page is open before the take starts
    # A scripted hand on the sliders keeps the arm moving: 20 mm back and forth in x.
    def script(t):
        meshcat.SetSliderValue("stylus x (mm)", 20.0 * math.sin(2 * math.pi * t / 3.0))

    try:
        # The replay is exported too (its cost is part of a take), into a scratch folder.
        with page, tempfile.TemporaryDirectory(prefix="bench-teleop-") as scratch:
            take = run_take(scenario, seed=1, visualization=visualization, duration=seconds,
                            realtime=False, title=f"{task}: bench",
                            replay_path=Path(scratch) / "replay.html", on_step=script,
                            progress=lambda line: None)  # fmt: skip
    finally:
        listener.close()
    # Each moving body's pose is one set_transform per visualizer publish.
    arm = [n for p, n in listener.transforms.items() if "/drake/illustration" in str(p)]
    print(
        f"{task}: {seconds:g} s simulated in {take.wall_seconds:.2f} s = "
        f"{seconds / take.wall_seconds:.2f}x real time with the live page"
        + (" rendered in headless Chromium" if chromium else "")
        + f" and the replay recorder; the page received each arm body's pose at "
        f"{max(arm, default=0) / seconds:.0f} Hz ({len(arm)} paths) and the page's "
        f"read-outs at {take.page_updates / seconds:.0f} Hz"
    )


def latency(seconds):
    scenario = load_scenario(shipped_scenario("cotter_pin"))
    visualization = Visualization(0)
    meshcat = visualization.meshcat
    listener = Listener(meshcat)
    sends = []

    def sender():
        time.sleep(0.8)
        value = 1.0
        while not listener.stop:
            buttons = [0.0] * 17
            sends.append((time.monotonic(), value))
            pad = dict(index=0, button_values=buttons, axes=[value, 0.0, 0.0, 0.0])
            listener.send(type="gamepad", name="", gamepad=pad)
            value = 0.0 if value else 1.0
            time.sleep(0.337 if value == 0.0 else 0.291)

    thread = threading.Thread(target=sender, daemon=True)
    thread.start()
    try:
        take = run_take(scenario, seed=1, visualization=visualization, duration=seconds,
                        realtime=True, progress=lambda line: None, scene=False)  # fmt: skip
    finally:
        listener.close()
        thread.join(timeout=2)
    rows, times, walls = take.inputs.rows, take.inputs.time, take.inputs.wall_time
    axis = rows[:, COLUMNS.index("axis_0")]
    demo = take.demonstration
    seen, moved = [], []
    for sent_at, value in sends:
        if value != 1.0:
            continue
        later = np.nonzero((walls >= sent_at) & (axis == 1.0))[0]
        if len(later) == 0:
            continue
        k = later[0]
        seen.append(walls[k] - sent_at)
        # The stylus "moves" when it is 0.05 mm from where it was at that sample.
        x0 = np.interp(times[k], demo.time, demo.p_MS[:, 0])
        after = np.nonzero((demo.time >= times[k]) & (np.abs(demo.p_MS[:, 0] - x0) > 5e-5))[0]
        if len(after):
            moved.append(np.interp(demo.time[after[0]], times, walls) - sent_at)
    print(
        f"latency over {len(seen)} stick deflections at real time: message -> sampled "
        f"median {1e3 * np.median(seen):.1f} ms (max {1e3 * np.max(seen):.1f}); message -> "
        f"stylus moved 0.05 mm median {1e3 * np.median(moved):.1f} ms (max "
        f"{1e3 * np.max(moved):.1f}); real-time factor of the take "
        f"{take.inputs.end_time / take.wall_seconds:.2f}"
    )


def keyboard_latency(seconds):
    """Key presses in the real page (headless Chromium, DevTools) to the sampled slider."""
    scenario = load_scenario(shipped_scenario("cotter_pin"))
    visualization = Visualization(0)
    meshcat = visualization.meshcat
    presses = []
    with HeadlessPage(meshcat.web_url()) as page:

        def script(t):
            if not presses:
                deadline = time.monotonic() + 60
                while not page.evaluate("document.body.innerText.includes('stylus x')"):
                    if time.monotonic() > deadline:
                        raise RuntimeError("the page never showed its controls")
                    time.sleep(0.05)
            if t > 0.5 and (not presses or t - presses[-1][1] > 0.3):
                presses.append((time.monotonic(), t))
                page.press("ArrowRight")

        take = run_take(scenario, seed=1, visualization=visualization, duration=seconds,
                        realtime=True, on_step=script, progress=lambda line: None,
                        scene=False)  # fmt: skip
    slider = take.inputs.rows[:, COLUMNS.index("slider_x_mm")]
    walls = take.inputs.wall_time
    delays = []
    for n, (pressed_at, _) in enumerate(presses[1:], start=1):
        # After the n-th press the slider reads n steps of 2 mm over its start.
        later = np.nonzero((walls >= pressed_at) & (slider - slider[0] >= 2.0 * (n + 1) - 1e-9))[0]
        if len(later):
            delays.append(walls[later[0]] - pressed_at)
    print(
        f"key press in the page -> sampled slider, {len(delays)} presses at real time: median "
        f"{1e3 * np.median(delays):.1f} ms (max {1e3 * np.max(delays):.1f})"
    )


def screenshot(path):
    scenario = load_scenario(shipped_scenario("cotter_pin"))
    visualization = Visualization(0)
    meshcat = visualization.meshcat
    state = {}
    with HeadlessPage(meshcat.web_url(), size=(1280, 800)) as page:

        def script(t):
            if "ready" not in state:
                deadline = time.monotonic() + 60
                while not page.evaluate("document.body.innerText.includes('stylus x')"):
                    if time.monotonic() > deadline:
                        raise RuntimeError("the page never showed its controls")
                    time.sleep(0.05)
                page.evaluate("document.querySelector('.close-button') && "
                              "document.querySelector('.close-button').click()")  # fmt: skip
                state["ready"] = t
            elif t - state["ready"] < 2.0:
                page.press("KeyW")  # up: pull the pin
                page.press("KeyX")  # tense: a stiffer slave
            elif "shot" not in state:
                state["shot"] = page.screenshot()

        run_take(scenario, seed=1, visualization=visualization, duration=4.0, realtime=True,
                 on_step=script, progress=lambda line: None)  # fmt: skip
    write_bytes_atomic(path, state["shot"])
    print(f"wrote {path}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--screenshot", help="write a PNG of the live page there")
    parser.add_argument(
        "--chromium", action="store_true",
        help="also measure the speed with the page rendered in headless Chromium",
    )  # fmt: skip
    args = parser.parse_args()
    if args.screenshot:
        screenshot(args.screenshot)
        return
    for task in ("cotter_pin", "drawing"):
        speed(task, args.seconds)
        if args.chromium:
            speed(task, args.seconds, chromium=True)
    latency(args.seconds)
    if args.chromium:
        keyboard_latency(args.seconds)


if __name__ == "__main__":
    main()
