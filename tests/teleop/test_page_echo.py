"""The teleop page's local echo, in the real page (headless Chromium, real key events): the
stylus target (the blue cross) moves the moment a key goes down, by the page's own script,
with no simulation running, and the server's next published command reconciles it; and the
overlay, which writes only what changed, still shows each new state."""

import time

import numpy as np
import pytest

from hemg_drake.teleop.browser_inputs import SLIDER_X, SLIDER_Z, TAP_MM, MeshcatInputs
from hemg_drake.teleop.browser_page import TeleopPage
from hemg_drake.teleop.browser_server import TeleopPageServer
from tooling.headless_page import HeadlessPage  # tests/tooling: test tooling, not runtime
from tooling.teleop_page import wait_for

pytestmark = pytest.mark.browser

# A workspace map's linear part by hand: scale 2, the master's x onto W's -y, y onto z, z
# onto -x (not symmetric: a transposed map would put the cross elsewhere).
M = 2.0 * np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
P_WC = np.array([0.6, -0.8, 0.2])


def cross(page):
    return np.array(page.evaluate(
        "(() => { const p = viewer.scene_tree.find(['teleop', 'target']).object.position;"
        " return [p.x, p.y, p.z]; })()"
    ))  # fmt: skip


def wait_cross(page, expected, timeout=30.0):
    deadline = time.monotonic() + timeout
    while not np.allclose(cross(page), expected, atol=1e-9):
        if time.monotonic() > deadline:
            raise AssertionError(f"the cross is at {cross(page)}, expected {expected}")
        time.sleep(0.02)


def test_the_cross_moves_with_the_keys_at_once_and_the_server_reconciles_it(
    chromium, visualization, meshcat
):
    server = TeleopPageServer(meshcat, task="cotter_pin", scale=2.0)
    MeshcatInputs(meshcat, p_MS_initial=[0.0, 0.0, 0.0])  # the sliders, at 0 mm
    marks = TeleopPage(meshcat, k_min=10.0, k_max=200.0, server=server, echo_map=M)
    # The server's newest command: the target heading to P_WC, its sample's sliders 0 mm.
    marks.update(0.01, P_WC, np.zeros(3), 10.0, True, p_WT=P_WC - [0.001, 0, 0],
                 echo=(P_WC, [0.0, 0.0, 0.0]))  # fmt: skip
    with HeadlessPage(server.url()) as page:
        deadline = time.monotonic() + 120
        while not page.evaluate(f"!!(window.viewer && viewer.gui_controllers[{SLIDER_Z!r}])"):
            assert time.monotonic() < deadline, "the page never got its sliders"
            time.sleep(0.05)
        wait_for(page, "recording 0.0 s")
        wait_cross(page, P_WC)  # the command, over the published (lagging) target
        # No simulation runs: only the page's script can move the cross.
        page.press("ArrowRight")
        page.press("ArrowUp")  # away from the operator: stylus -z
        d = 1e-3 * np.array([TAP_MM, 0.0, -TAP_MM])
        wait_cross(page, P_WC + M @ d, timeout=2.0)
        sliders = [page.evaluate(f"viewer.gui_controllers[{name!r}].getValue()")
                   for name in (SLIDER_X, "stylus y (mm)", SLIDER_Z)]  # fmt: skip
        np.testing.assert_allclose(sliders, 1e3 * d, atol=1e-9)
        # The server samples the sliders and publishes where they send the target (here
        # 3 mm further in x than the keys: a gamepad's part): the cross follows it.
        later = P_WC + M @ (d + [0.003, 0.0, 0.0])
        marks.update(0.02, P_WC, np.zeros(3), 10.0, True, p_WT=P_WC, echo=(later, 1e3 * d))
        wait_cross(page, later)
        # The overlay: a new state and the K bar, written once they change.
        marks.update(0.5, P_WC, np.zeros(3), 105.0, True, p_WT=P_WC, echo=(later, 1e3 * d))
        wait_for(page, "recording 0.5 s")
        assert page.evaluate("document.getElementById('hemg-k').textContent") == "105 N/m"
        assert page.evaluate("document.getElementById('hemg-kbar').style.width") == "50%"
