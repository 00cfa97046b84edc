"""Meshcat replays: one self-contained HTML, no servers left behind, rendered by Chromium."""

import base64
import gc
import os
import re
import socket
import threading

import matplotlib.image
import msgpack
import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from hemg_drake.diagrams.visualization import Visualization, apply_visualization
from hemg_drake.robots.baxter import FLOOR_Z, add_baxter_arm
from hemg_drake.scenario import Scenario
from hemg_drake.viz import screenshot
from hemg_drake.viz.recording import (
    ELBOW_RISE,
    RIGHT_SHOULDER_W,
    ReplayRecorder,
    camera_framing,
    frame_task,
)
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


# A task at the arm's front right (the cotter pin's ring and its pull), and the shoulder.
PLAN_POINTS = np.array([[0.64, -0.84, 0.12], [0.64, -0.84, 0.22]])
TASK_POINTS = np.vstack([RIGHT_SHOULDER_W, np.add(RIGHT_SHOULDER_W, [0, 0, ELBOW_RISE]),
                         PLAN_POINTS])
TITLE = "cotter pin: demonstration 2 <seed 101> & co"


def _record_arm(path, duration=0.3, **recorder_options):
    """Record the bare arm falling under gravity from its home pose, visualised as the
    scenario's VisualizationConfig says; return the server's port."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    add_baxter_arm(plant)  # starts at home
    plant.Finalize()
    visualization = Visualization()
    apply_visualization(Scenario().visualization, builder, plant=plant,
                        scene_graph=scene_graph, visualization=visualization)  # fmt: skip
    port = visualization.port()
    diagram = builder.Build()
    recorder = ReplayRecorder(floor_z=FLOOR_Z, **recorder_options)
    recorder.start(diagram, visualization.meshcat)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(duration)
    assert recorder.stop_and_export(path) == path
    return port


@pytest.fixture(scope="module")
def replay(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay") / "replay.html"
    _record_arm(path, title=TITLE, view=frame_task(PLAN_POINTS))
    return path


def _commands(html):
    """Meshcat's commands embedded in a static page (base64 msgpack), in order."""
    return [msgpack.unpackb(base64.b64decode(data), raw=False, strict_map_key=False)
            for data in re.findall(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)",
                                   html)]


def _to_three(p_W):
    """Drake's z-up world to three.js's y-up frame, written out here: (x, z, -y)."""
    return [p_W[0], p_W[2], -p_W[1]]


def test_replay_has_its_title(replay):
    html = replay.read_text(encoding="utf-8")
    titles = re.findall(r"<title>(.*?)</title>", html, re.DOTALL)
    assert titles == ["cotter pin: demonstration 2 &lt;seed 101&gt; &amp; co"]
    assert "Drake MeshCat" not in html


def test_replay_opens_on_the_framed_camera(replay):
    camera, target = camera_framing(TASK_POINTS)
    commands = _commands(replay.read_text(encoding="utf-8"))
    positions = [c["value"] for c in commands if c["type"] == "set_property"
                 and c["path"] == "/Cameras/default/rotated/<object>"
                 and c["property"] == "position"]
    targets = [c["value"] for c in commands if c["type"] == "set_target"]
    np.testing.assert_allclose(positions[-1], _to_three(camera))
    np.testing.assert_allclose(targets[-1], _to_three(target))


def test_frame_task_includes_the_shoulder_where_the_plant_has_it():
    plant = MultibodyPlant(0.0)
    add_baxter_arm(plant)
    plant.Finalize()
    shoulder = plant.GetBodyByName("right_upper_shoulder").EvalPoseInWorld(
        plant.CreateDefaultContext()).translation()
    np.testing.assert_allclose(RIGHT_SHOULDER_W, shoulder, atol=1e-6)
    for got, expected in zip(frame_task(PLAN_POINTS), camera_framing(TASK_POINTS), strict=True):
        np.testing.assert_array_equal(got, expected)


def test_frame_task_sees_every_link_of_the_arm_at_home():
    plant = MultibodyPlant(0.0)
    arm = add_baxter_arm(plant)
    plant.Finalize()
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, arm.model_instance, arm.home_positions)
    links = [plant.get_body(i).EvalPoseInWorld(context).translation()
             for i in plant.GetBodyIndices(arm.model_instance)
             if plant.get_body(i).name().startswith("right_")]
    camera, target = frame_task(PLAN_POINTS)
    axis = (target - camera) / np.linalg.norm(target - camera)
    for p_W in links:
        ray = p_W - camera
        assert np.degrees(np.arccos(ray @ axis / np.linalg.norm(ray))) < 37.5 / 1.2
    with pytest.raises(ValueError, match="points_W"):
        frame_task([0.0, 0.0, 0.0])


def test_framing_puts_every_point_in_the_view_cone():
    camera, target = camera_framing(TASK_POINTS, margin=1.15)
    np.testing.assert_allclose(target, (TASK_POINTS.min(0) + TASK_POINTS.max(0)) / 2)
    axis = (target - camera) / np.linalg.norm(target - camera)
    for point in TASK_POINTS:
        ray = point - camera
        angle = np.degrees(np.arccos(ray @ axis / np.linalg.norm(ray)))
        assert angle < 37.5 / 1.15  # inside the vertical half-angle, with the margin
    # The camera looks from the front left and above, not from below or behind the robot.
    assert camera[0] > target[0] and camera[1] > target[1] and camera[2] > target[2]
    # Tighter than the old default camera, which stood 2 m from a point below the task.
    assert np.linalg.norm(camera - target) < 1.2


@pytest.mark.parametrize(
    "kwargs, message",
    [({"points_W": np.zeros((0, 3))}, "points_W"), ({"points_W": [[0.0, 0.0]]}, "points_W"),
     ({"points_W": [[np.nan, 0, 0]]}, "NaN"), ({"view_from": (0, 0, 0)}, "view_from"),
     ({"fov_deg": 0.0}, "fov_deg"), ({"margin": 0.5}, "margin")],
)
def test_framing_bad_input(kwargs, message):
    kwargs = {"points_W": TASK_POINTS, **kwargs}
    with pytest.raises(ValueError, match=message):
        camera_framing(**kwargs)


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
    with pytest.raises(ValueError, match="start"):
        recorder.stop_and_export(tmp_path / "x.html")
    with pytest.raises(ValueError, match="camera_in_world"):
        ReplayRecorder(camera_in_world=(1.0, 2.0))
    with pytest.raises(ValueError, match="differ"):
        ReplayRecorder(camera_in_world=(1.0, 2.0, 3.0), target_in_world=(1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match="not both"):
        ReplayRecorder(view=camera_framing(TASK_POINTS), camera_in_world=(1.0, 2.0, 3.0))
    for title in ("", "two\nlines", None):
        with pytest.raises(ValueError, match="title"):
            ReplayRecorder(title=title)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    plant.Finalize()
    bare = builder.Build()
    bare.set_name("bare")
    visualization = Visualization()
    with pytest.raises(ValueError, match="'bare' has no Meshcat visualiser"):
        recorder.start(bare, visualization.meshcat)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    plant.Finalize()
    apply_visualization(Scenario().visualization, builder, plant=plant,
                        scene_graph=scene_graph, visualization=visualization)  # fmt: skip
    diagram = builder.Build()
    recorder.start(diagram, visualization.meshcat)
    with pytest.raises(ValueError, match="already recording"):
        recorder.start(diagram, visualization.meshcat)
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


@pytest.mark.browser
def test_framed_replay_shows_the_arm_near_the_centre(replay, chromium, tmp_path):
    png = render_html_to_png(replay, tmp_path / "framed.png", size=(800, 600))
    rgb = matplotlib.image.imread(png)[..., :3]
    red = (rgb[..., 0] > 0.5) & (rgb[..., 1] < 0.25) & (rgb[..., 2] < 0.25)
    rows, columns = np.nonzero(red)
    assert len(rows) > 2000  # closer than the old default view (0.3-0.8 % of the picture)
    # The red arm's centroid lies in the middle half of the picture both ways.
    assert abs(columns.mean() - 400) < 200 and abs(rows.mean() - 300) < 150


# --- a station's replay, recorded on the visualiser ApplyVisualizationConfig added -------


def _replay_payload(path):
    """The binary Meshcat messages embedded (base64) in an HTML replay."""
    html = path.read_text()
    return b"".join(base64.b64decode(chunk) for chunk in re.findall(r"base64,([A-Za-z0-9+/=]+)", html))


@pytest.fixture(scope="module")
def drawing_replay(tmp_path_factory):
    """1.8 s of the drawing's demonstration (the first stroke starts at about 1.4 s: a short
    line of ink), recorded with record_run; (path, demonstration)."""
    from hemg_drake.diagrams.demonstration import build_demonstration_diagram, run_demonstration
    from hemg_drake.scenario import load_scenario, shipped_scenario
    from hemg_drake.viz.recording import record_run

    scenario = load_scenario(shipped_scenario("drawing"), overrides=["duration=1.8"])
    built = build_demonstration_diagram(scenario, visualization=Visualization())
    path = tmp_path_factory.mktemp("drawing") / "replay.html"
    demo = record_run(built, lambda b: run_demonstration(b, scenario.seed), path,
                      title="drawing: demonstration 1")  # fmt: skip
    return path, demo


def test_a_station_replay_holds_the_ink_the_title_and_the_frames(drawing_replay):
    from hemg_drake.viz.ink import in_contact

    path, demo = drawing_replay
    assert in_contact(demo.f_WE).sum() > 10
    payload = _replay_payload(path)
    assert b"/ink/stroke_0/piece_0" in payload and b"/ink/stroke_1" not in payload
    assert b"/drake/illustration/" in payload  # the arm, from ApplyVisualizationConfig's visualiser
    assert re.findall(r"<title>(.*?)</title>", path.read_text()) == ["drawing: demonstration 1"]
    # 32 frames per second (the scenario's visualization.publish_period), over 1.8 s.
    animation = [c for c in _commands(path.read_text()) if c["type"] == "set_animation"]
    assert len(animation) == 1 and animation[0]["options"]["play"] is not None
    times = [key["time"] for clip in animation[0]["animations"]
             for track in clip["clip"]["tracks"] for key in track["keys"]]  # fmt: skip
    # Frames 0 .. 57: from the initial publish to the last one at 57 / 32 s <= 1.8 s.
    assert (min(times), max(times)) == (0, int(1.8 * 32))


def test_record_run_needs_a_visualised_diagram(tmp_path):
    from hemg_drake.diagrams.demonstration import build_demonstration_diagram, run_demonstration
    from hemg_drake.scenario import load_scenario, shipped_scenario
    from hemg_drake.viz.recording import record_run

    scenario = load_scenario(shipped_scenario("cotter_pin"), overrides=["duration=0.05"])
    built = build_demonstration_diagram(scenario, scene=False)
    with pytest.raises(ValueError, match="visualization=Visualization"):
        record_run(built, lambda b: run_demonstration(b, 0), tmp_path / "x.html", title="x")


@pytest.mark.browser
def test_a_station_replay_renders_the_arm(drawing_replay, chromium, tmp_path):
    path, _ = drawing_replay
    png = render_html_to_png(path, tmp_path / "drawing.png", size=(800, 600))
    assert _arm_pixels(png) > 2000  # framed on the task, as the bare arm's replay
