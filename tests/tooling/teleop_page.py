"""Reading the teleop page (``hemg-drake teleop``'s served page) as a person does: its state
line, and waiting for its controls or for a state. Shared by the page's tests and
benchmarks/bench_teleop_page.py."""

import time

from hemg_drake.teleop.browser_inputs import KEYS


def state(page):
    """The page's state line (waiting, recording, ...), "" before it has one."""
    return page.evaluate("document.getElementById('hemg-state').textContent") or ""


def controls_ready(page, timeout=300.0):
    """Wait until Meshcat has given the page its buttons and every slider the keys move
    (each arrives in a message of its own: a key whose slider is not there yet does nothing)."""
    deadline = time.monotonic() + timeout
    names = ["Start take", *KEYS]
    while not page.evaluate("!!(window.viewer && %s)" % " && ".join(
        f"viewer.gui_controllers[{name!r}]" for name in names
    )):  # fmt: skip
        if time.monotonic() > deadline:
            raise TimeoutError("the page never got its controls")
        time.sleep(0.05)


def wait_for(page, text, timeout=120.0):
    """Wait until the state line says ``text``."""
    deadline = time.monotonic() + timeout
    while text not in state(page):
        if time.monotonic() > deadline:
            raise TimeoutError(f"the page never said {text!r} (it says {state(page)!r})")
        time.sleep(0.05)


def end_take(page, verdict="KeyK"):
    """End the take (Escape), wait for the page to say so, then keep (K) or discard (D) it;
    returns the hint the page showed with "ended" (a drawing's score against the template)."""
    page.press("Escape")
    wait_for(page, "ended")
    hint = page.evaluate("document.getElementById('hemg-hint').textContent") or ""
    page.press(verdict)
    return hint
