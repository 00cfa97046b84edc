"""Meshcat replays: one self-contained HTML, no servers left behind, rendered by Chromium."""

import gc
import os
import re
import socket
import threading

import matplotlib.image
import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from hemg_drake.robots.baxter import FLOOR_Z, add_baxter_arm
from hemg_drake.viz import screenshot
from hemg_drake.viz.recording import ReplayRecorder
from hemg_drake.viz.screenshot import render_html_to_png

# Network references that would make a browser fetch something to render the page.
NETWORK_PATTERNS = [
    r"<script[^>]*\bsrc\s*=\s*[\"']?\s*(https?:)?//",
    r"<link[^>]*\bhref\s*=\s*[\"']?\s*(https?:)?//",
    r"<img[^>]*\bsrc\s*=\s*[\"']?\s*(https?:)?//",
    r"\bimport\s*\(?\s*[\"']https?://",
    r"\bfrom\s+[\"']https?://",
    r"url\(\s*[\"']?https?://",
]


def _os_threads():
    return len(os.listdir("/proc/self/task"))


def _record_arm(path, duration=0.3):
    """Record the bare arm falling under gravity from its home pose; return the server's port."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    add_baxter_arm(plant)  # starts at home
    plant.Finalize()
    recorder = ReplayRecorder(floor_z=FLOOR_Z)
    recorder.add_to_builder(builder, scene_graph)
    port = recorder.meshcat.port()
    simulator = Simulator(builder.Build())
    recorder.start()
    simulator.AdvanceTo(duration)
    assert recorder.stop_and_export(path) == path
    return port


@pytest.fixture(scope="module")
def replay(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay") / "replay.html"
    _record_arm(path)
    return path


def _network_references(html):
    return [m.group(0) for p in NETWORK_PATTERNS for m in re.finditer(p, html, re.IGNORECASE)]


def test_html_is_self_contained(replay):
    html = replay.read_text(encoding="utf-8")
    assert html.lstrip().lower().startswith("<!doctype html") or "<html" in html[:2000].lower()
    assert len(html) > 100_000  # meshcat's scripts are inlined, not linked
    assert _network_references(html) == []
    # The check itself catches a linked script.
    assert _network_references('<script src="https://cdn.example/three.js"></script>')
    # Atomic write: no temporary file remains beside the replay.
    assert [p.name for p in replay.parent.iterdir()] == ["replay.html"]


def test_meshcat_server_is_released(tmp_path):
    gc.collect()
    threads_before, python_threads_before = _os_threads(), threading.active_count()
    port = _record_arm(tmp_path / "replay.html", duration=0.05)
    gc.collect()  # pydrake objects form reference cycles
    assert _os_threads() == threads_before
    assert threading.active_count() == python_threads_before
    with socket.socket() as probe:
        assert probe.connect_ex(("localhost", port)) != 0, "Meshcat still listens"


def test_recorder_errors(tmp_path):
    recorder = ReplayRecorder()
    with pytest.raises(ValueError, match="add_to_builder"):
        recorder.start()
    with pytest.raises(ValueError, match="add_to_builder"):
        recorder.stop_and_export(tmp_path / "x.html")
    with pytest.raises(ValueError, match="publish_period"):
        ReplayRecorder(publish_period=0.0)
    with pytest.raises(ValueError, match="camera_in_world"):
        ReplayRecorder(camera_in_world=(1.0, 2.0))
    builder = DiagramBuilder()
    _, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    recorder.add_to_builder(builder, scene_graph)
    with pytest.raises(ValueError, match="already attached"):
        recorder.add_to_builder(builder, scene_graph)
    recorder.close()


def test_render_errors(tmp_path, monkeypatch):
    with pytest.raises(FileNotFoundError, match="missing.html"):
        render_html_to_png(tmp_path / "missing.html", tmp_path / "x.png")
    page = tmp_path / "page.html"
    page.write_text("<html></html>")
    monkeypatch.setattr(screenshot, "find_chromium", lambda: None)
    with pytest.raises(FileNotFoundError, match="chromium"):
        render_html_to_png(page, tmp_path / "x.png")


def _arm_pixels(png):
    """Pixels of the arm's red (the URDF's arm_red, shaded)."""
    rgb = matplotlib.image.imread(png)[..., :3]
    red, green, blue = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return int(np.count_nonzero((red > 0.5) & (green < 0.25) & (blue < 0.25)))


@pytest.mark.browser
def test_screenshot_shows_the_arm(replay, chromium, tmp_path):
    png = render_html_to_png(replay, tmp_path / "replay.png", size=(800, 600))
    assert matplotlib.image.imread(png).shape[:2] == (600, 800)
    # The arm covers about 0.3-0.8 % of the picture from the default camera.
    assert _arm_pixels(png) > 500


@pytest.mark.browser
def test_blank_page_has_no_arm(chromium, tmp_path):
    page = tmp_path / "blank.html"
    page.write_text("<!DOCTYPE html><html><body style='background:#ccc'></body></html>")
    png = render_html_to_png(page, tmp_path / "blank.png", size=(400, 300))
    assert _arm_pixels(png) == 0
