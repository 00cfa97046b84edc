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

``--chromium``: the speed again with Drake's page open in headless Chromium on the same
cores (software WebGL, the worst case for a browser on this machine). The teleop page a
person opens (its keys, legend and takes), its key-to-motion latency and its screenshot:
``benchmarks/bench_teleop_page.py``.

    .venv/bin/python benchmarks/bench_teleop_browser.py [--seconds 6] [--chromium]
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


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument(
        "--chromium", action="store_true",
        help="also measure the speed with the page rendered in headless Chromium",
    )  # fmt: skip
    args = parser.parse_args()
    for task in ("cotter_pin", "drawing"):
        speed(task, args.seconds)
        if args.chromium:
            speed(task, args.seconds, chromium=True)
    latency(args.seconds)


if __name__ == "__main__":
    main()
