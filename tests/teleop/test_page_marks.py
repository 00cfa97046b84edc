"""What the teleop page draws and serves, without a browser: the operator's view, live ink,
the template, the force arrow's direction, and the served page and state."""

import json
import urllib.request

import numpy as np
import pytest

from hemg_drake.diagrams.visualization import Visualization
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.teleop.browser_page import TeleopPage, operator_view
from hemg_drake.teleop.browser_server import TeleopPageServer


@pytest.mark.parametrize("task", ["cotter_pin", "drawing"])
def test_the_operator_view_has_the_keys_directions_on_screen(task):
    scenario = load_scenario(shipped_scenario(task))
    to_W = scenario.workspace_mapping().master_to_slave
    camera, target = operator_view(scenario.task_plan().points, to_W)
    forward = (target - camera) / np.linalg.norm(target - camera)
    # A camera with world z up: screen right is forward x z, screen up is right x forward.
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    unit = lambda v: v / np.linalg.norm(v)  # noqa: E731
    master_x = unit(to_W(np.array([1.0, 0, 0])) - to_W(np.zeros(3)))  # ArrowRight
    master_y = unit(to_W(np.array([0, 1.0, 0])) - to_W(np.zeros(3)))  # W
    away = unit(to_W(np.array([0, 0, -1.0])) - to_W(np.zeros(3)))  # ArrowUp
    assert right @ master_x > 0.99
    assert up @ master_y > 0.8
    assert forward @ away > 0.8  # away from the operator is into the screen
    # Framed on the task: the task's middle is looked at from 0.45-1 m.
    assert 0.45 <= np.linalg.norm(target - camera) <= 1.0


def test_live_ink_template_and_the_force_the_tool_applies():
    meshcat = Visualization(0).meshcat
    page = TeleopPage(meshcat, k_min=10.0, k_max=200.0)
    page.draw_ink(0.1, 0.05)
    page.show_template([np.array([[0.5, 0.0, 0.3], [0.6, 0.0, 0.3]])], 0.1)
    assert meshcat.HasPath("/teleop/template/0")
    touch, free = [0.0, 0.0, 2.0], [0.0, 0.0, 0.01]
    for k in range(3):
        page.update(0.01 * k, [0.5 + 0.001 * k, 0, 0.1], touch, 50.0, True)
    assert meshcat.HasPath("/teleop/ink/0/0") and not meshcat.HasPath("/teleop/ink/1/0")
    page.update(0.1, [0.6, 0, 0.12], free, 50.0, True)  # lifted: the stroke ends
    for k in range(TeleopPage.INK_PIECE + 2):
        page.update(0.2 + 0.01 * k, [0.6 + 0.001 * k, 0, 0.1], touch, 50.0, True)
    assert meshcat.HasPath("/teleop/ink/1/0") and meshcat.HasPath("/teleop/ink/1/1")
    assert not meshcat.HasPath("/teleop/ink/2/0")


def test_the_server_serves_the_page_and_its_state():
    meshcat = Visualization(0).meshcat
    server = TeleopPageServer(meshcat, task="drawing", scale=2.0, port=0)
    try:
        html = urllib.request.urlopen(server.url(), timeout=10).read().decode()
        assert f"ws://localhost:{meshcat.port()}/" in html and "hemg-legend" in html
        assert f'src="http://localhost:{meshcat.port()}/cas-v1/' in html
        assert "press it 2-3 mm into the paper" in html
        page = TeleopPage(meshcat, k_min=10.0, k_max=200.0, server=server, take=3)
        page.update(1.5, [0.5, 0, 0.1], [0.0, 0.0, -4.0], 120.0, True, activation=0.6,
                    rate=0.5)  # fmt: skip
        state = json.loads(urllib.request.urlopen(server.url() + "state", timeout=10).read())
        assert state["headline"] == "take 3: recording 1.5 s" and state["K"] == 120.0
        assert state["force"] == 4.0 and state["activation"] == 0.6
        assert "0.50x real time" in state["slow"]
        page.update(1.6, [0.5, 0, 0.1], [0.0, 0.0, -4.0], 120.0, True, rate=0.9)
        state = json.loads(urllib.request.urlopen(server.url() + "state", timeout=10).read())
        assert state["slow"] == ""
    finally:
        server.close()
    with pytest.raises(ValueError, match="in use"):
        with __import__("socket").socket() as taken:
            taken.bind(("localhost", 0))
            taken.listen(1)
            TeleopPageServer(meshcat, task="drawing", scale=2.0, port=taken.getsockname()[1])
