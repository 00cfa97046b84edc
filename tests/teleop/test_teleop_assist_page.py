"""The assist at the real page (issue 26): ``hemg-drake teleop`` with a learnt model, driven in
headless Chromium by the closed-loop key driver (tests/tooling/page_driver.py). The page shows
the assist's weight and phase, A switches it off and on (logged with the inputs), and the
pin comes out with fewer key presses with the assist on than off (counts printed)."""

import subprocess
import sys

import pytest

from hemg_drake.tasks.plans import pin_length
from hemg_drake.teleop.browser_inputs import COLUMNS, load_inputs
from tooling.headless_page import HeadlessPage
from tooling.page_driver import PageDriver, pull_pin
from tooling.teleop_page import ROOT, Command, controls_ready, end_take, wait_for

pytestmark = [pytest.mark.browser, pytest.mark.person, pytest.mark.timeout(3600)]


def cli(*args):
    import os

    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-m", "hemg_drake.cli", *args], env=env,
                          capture_output=True, text=True, timeout=1200)  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


@pytest.fixture(scope="module")
def pin_model(tmp_path_factory):
    """A model learnt from three simulated demonstrations of the pin (the shipped scenario)."""
    run = tmp_path_factory.mktemp("learnt") / "pin"
    cli("demonstrate", "cotter_pin", "--out", str(run), "--demos", "3", "--no-replay")
    cli("learn", str(run))
    return run / "model.npz"


def pin_take(tmp_path, *settings, toggle=False):
    """One pin take at the page, pulled by the driver; (presses, take seconds, page texts,
    inputs log)."""
    run = tmp_path / "run"
    sets = [a for s in settings for a in ("--set", s)]
    command = Command("cotter_pin", "--out", str(run), "--port", "0", "--no-replay", *sets)
    seen = {}
    try:
        with HeadlessPage(command.url) as page:
            wait_for(page, "waiting")
            controls_ready(page)
            seen["legend"] = page.evaluate("document.getElementById('hemg-legend').innerText")
            page.press("Enter")
            wait_for(page, "recording")
            driver = PageDriver(page)
            driver.wait_take_time(0.3)
            out = pull_pin(driver, pin_length=pin_length())
            seen["out"] = out
            seen["assist"] = page.evaluate(
                "document.getElementById('hemg-assist').style.display") == "block"
            if seen["assist"]:
                seen["weight_on"] = driver.number("hemg-w")
                seen["phase"] = driver.text("hemg-phase")
                seen["state_on"] = driver.text("hemg-assist-state")
            presses = sum(driver.presses.values())
            if toggle:  # A switches the assist off: the weight falls, the page says so
                page.press("KeyA")
                driver.wait_take_time(0.8)
                seen["state_off"] = driver.text("hemg-assist-state")
                seen["weight_off"] = driver.number("hemg-w")
            take_time = driver.take_time()
            end_take(page)
            code, output = command.finish()
    finally:
        command.stop()
    assert code == 0 and "1 take kept" in output, output
    return presses, take_time, seen, load_inputs(run / "inputs_1.npz"), driver.presses


def test_the_pin_comes_out_with_fewer_presses_with_the_assist(pin_model, tmp_path, chromium):
    alone = pin_take(tmp_path / "alone")
    assisted = pin_take(tmp_path / "assisted", "assist.mode=fixed", f"assist.model={pin_model}",
                        toggle=True)  # fmt: skip
    print(f"\npin at the page, key presses: assist off {alone[0]} ({dict(alone[4])}, "
          f"{alone[1]:.1f} s), assist fixed {assisted[0]} ({dict(assisted[4])}, "
          f"{assisted[1]:.1f} s)")  # fmt: skip
    # The page showed the assist only when the scenario has one, and A in the legend.
    assert not alone[2]["assist"] and "assist" not in alone[2]["legend"]
    seen = assisted[2]
    assert seen["assist"] and "assist on (fixed) / off" in seen["legend"]
    assert seen["state_on"].startswith("on (fixed)") and seen["weight_on"] > 0.3
    assert "state" in seen["phase"] and "confidence" in seen["phase"]
    # A switched it off: the page says so, the weight fell, the click is in the inputs log.
    assert seen["state_off"].startswith("off") and seen["weight_off"] < 0.05
    clicks = assisted[3].rows[:, COLUMNS.index("assist_clicks")]
    assert clicks[-1] - clicks[0] == 1
    # Measured: fewer presses with the assist on.
    assert assisted[0] < alone[0]
