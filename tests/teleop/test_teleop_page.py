"""The teleop page as a person uses it: ``hemg-drake teleop`` in a process of its own, the
printed URL opened in headless Chromium, real key events (DevTools ``Input.dispatchKeyEvent``)
and what the page shows read back from it."""

import json
import time
import urllib.request

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from hemg_drake.learning.demos import load_dataset
from hemg_drake.teleop.browser import BrowserMaster
from hemg_drake.teleop.browser_inputs import (
    ACTIVATION_HOLD_S,
    ACTIVATION_TAP,
    COLUMNS,
    HOLD_DELAY,
    TAP_MM,
    LoggedInputs,
    load_inputs,
)
from tooling.headless_page import HeadlessPage  # tests/tooling: test tooling, not runtime
from tooling.page_driver import PageDriver
from tooling.teleop_page import Command, controls_ready, end_take, state, wait_for

pytestmark = pytest.mark.browser


def test_takes_start_end_discard_keep_in_the_real_page(chromium, tmp_path):
    run = tmp_path / "run"
    command = Command("cotter_pin", "--out", str(run), "--port", "0", "--no-replay")
    try:
        with HeadlessPage(command.url, size=(1280, 800)) as page:
            wait_for(page, "waiting")
            controls_ready(page)
            # On load: the legend, the task's line and Meshcat's controls open.
            text = page.evaluate("document.getElementById('hemg-panel').innerText")
            for said in ("start a take", "end the take", "keep", "discard", "squeeze",
                         "a tap moves the tool 1 mm"):  # fmt: skip
                assert said in text, text
            assert page.evaluate("viewer.gui.closed") is False
            # Headless Chromium renders in software: the scene without multisampling.
            assert page.evaluate("window.hemgSoftwareRendering") is True
            assert page.evaluate("viewer.renderer.getContext().getContextAttributes().antialias") is False
            # ... at half the resolution, without Meshcat's real-time plot (a frame each
            # redraw), at a frame rate paced by the simulation's: hand values of the law.
            assert page.evaluate("viewer.renderer.getPixelRatio()") == 0.5
            assert page.evaluate(
                "getComputedStyle(document.getElementById('stats-plot')).display") == "none"
            paced = page.evaluate("[[8, 0.5], [4, 0.9], [2, 0.1], [2, 1.0], [14, 1.2], [15, 1.0],"
                                  " [8, 0.98], [8, 0.97], [8, 0.99], [8, 0.9699]]"
                                  ".map(([f, r]) => hemgPace.nextFps(f, r))")  # fmt: skip
            assert paced == [4, 2, 2, 3, 15, 15, 8, 8, 9, 4]
            box = page.evaluate("JSON.stringify(document.getElementById('hemg-panel')"
                                ".getBoundingClientRect())")  # fmt: skip
            assert '"x":8' in box
            (tmp_path / "page.png").write_bytes(page.screenshot())
            time.sleep(2.0)
            assert "waiting" in state(page)  # a take never starts by itself
            # Take 1: started, moved, ended, discarded.
            page.press("Enter")
            wait_for(page, "recording")
            squeeze = "viewer.gui_controllers['activation'].getValue()"
            before = page.evaluate(squeeze)
            page.key("keyDown", "KeyX")
            held_from = time.monotonic()
            time.sleep(0.8)
            page.key("keyUp", "KeyX")
            held = time.monotonic() - held_from
            # A held key in wall-clock time, in the page's paced frames too: the tap, then
            # ACTIVATION_HOLD_S per second past the hold delay, up to the release.
            expected = ACTIVATION_TAP + ACTIVATION_HOLD_S * (held - HOLD_DELAY)
            assert page.evaluate(squeeze) - before == pytest.approx(expected, abs=0.05)
            end_take(page, "KeyD")
            wait_for(page, "discarded")
            assert not (run / "dataset.npz").exists()
            time.sleep(2.0)
            assert "recording" not in state(page)  # the next does not start by itself
            wait_for(page, "waiting")  # and its line still says how the last one ended
            assert "(last: discarded)" in state(page), state(page)
            # Take 1 again: four taps to the right, ended, kept.
            page.press("Enter")
            wait_for(page, "recording")
            for _ in range(4):
                page.press("ArrowRight")
                time.sleep(0.15)
            time.sleep(0.5)
            # The server's real-time factor reaches the page, which paces on it.
            with urllib.request.urlopen(command.url + "state") as reply:
                assert 0.0 < json.load(reply)["rate"] < 10.0
            assert page.evaluate("hemgPace.paced()") >= 1
            end_take(page)
            code, out = command.finish()
    finally:
        command.stop()
    assert code == 0, out
    assert "take not kept (discarded); nothing written" in out and "1 take kept" in out
    demos, metadata = load_dataset(run / "dataset.npz")
    assert len(demos) == 1 and metadata["operators"] == ["browser"]
    log = load_inputs(run / "inputs_1.npz")
    slider = log.rows[:, COLUMNS.index("slider_x_mm")]
    assert slider[-1] - slider[0] == pytest.approx(4 * TAP_MM, abs=1e-9)
    # The log re-driving a master alone: its target moved exactly the four taps.
    p0 = np.array([0.0, -0.025, 0.0])
    master = BrowserMaster(source=LoggedInputs(log.time, log.rows), p_MS_initial=p0)
    simulator = Simulator(master)
    simulator.AdvanceTo(log.end_time)
    target = master.GetOutputPort("p_MT").Eval(simulator.get_context())
    assert target[0] - p0[0] == pytest.approx(4e-3 * TAP_MM, abs=1e-12)
    # Trimmed: the demonstration starts 0.2 s before the first tap.
    first = log.time[np.flatnonzero(np.diff(slider))[0] + 1]
    assert demos[0].time[-1] <= log.end_time - first + 0.2 + 1e-9


def test_closing_the_page_saves_nothing(chromium, tmp_path):
    run = tmp_path / "run"
    command = Command("cotter_pin", "--out", str(run), "--port", "0", "--no-replay")
    try:
        with HeadlessPage(command.url) as page:
            wait_for(page, "waiting")
            controls_ready(page)
            page.press("Enter")
            wait_for(page, "recording")
            page.key("keyDown", "KeyW")
            time.sleep(0.5)
        # The browser is gone mid-take, the key still held.
        code, out = command.finish()
    finally:
        command.stop()
    assert code == 0, out
    assert "the page was closed: not saved" in out and "0 takes kept" in out
    assert not run.exists() or not any(run.iterdir())


def test_a_drawing_take_shows_ink_on_the_template_as_it_is_drawn(chromium, tmp_path):
    command = Command("drawing", "--out", str(tmp_path / "run"), "--port", "0", "--no-replay")
    children = "Object.keys(viewer.scene_tree.find(['teleop', '{}']).children).length"
    try:
        with HeadlessPage(command.url) as page:
            wait_for(page, "waiting")
            controls_ready(page)
            assert page.evaluate(children.format("template")) == 3  # the three strokes
            page.press("Enter")
            wait_for(page, "recording")
            # The pen down onto the sheet (30 mm at 20 mm/s), held as a person holds it: until
            # the force read-out shows contact, then a moment more (into the paper).
            driver = PageDriver(page)
            deadline = time.monotonic() + 120
            while not driver.number("hemg-f") >= 0.5:  # (NaN: no read-out yet)
                assert time.monotonic() < deadline, "S never brought the pen onto the sheet"
                page.key("keyDown", "KeyS")
                time.sleep(0.5)
            time.sleep(0.15)
            page.key("keyUp", "KeyS")
            page.key("keyDown", "ArrowRight")  # and along it
            time.sleep(1.5)
            page.key("keyUp", "ArrowRight")
            deadline = time.monotonic() + 120
            while not page.evaluate(children.format("ink")):
                panel = page.evaluate("document.getElementById('hemg-panel').innerText")
                sliders = page.evaluate("JSON.stringify(Object.fromEntries(Object.entries("
                                        "viewer.gui_controllers).map(([k, c]) => [k, c.getValue()])))")  # fmt: skip
                assert time.monotonic() < deadline, f"no ink appeared: {panel[:300]} {sliders}"
                time.sleep(0.2)
            (tmp_path / "drawing.png").write_bytes(page.screenshot())
            end_take(page)
            code, out = command.finish()
    finally:
        command.stop()
    assert code == 0 and "1 take kept" in out, out
