"""Reading the teleop page (``hemg-drake teleop``'s served page) as a person does: its state
line, and waiting for its controls or for a state; the command itself, run in a process of its
own. Shared by the page's tests, benchmarks/bench_teleop_page.py and page_picture.py."""

import os
import subprocess
import sys
import time
from pathlib import Path

from hemg_drake.teleop.browser_inputs import KEYS

ROOT = Path(__file__).resolve().parents[2]


class Command:
    """``hemg-drake teleop`` running in a process of its own, its output read line by line:
    ``url`` the page it printed first."""

    def __init__(self, *args):
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        self.process = subprocess.Popen(
            [sys.executable, "-m", "hemg_drake.cli", "teleop", *args], stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True, env=env,
        )  # fmt: skip
        self.first = self.process.stdout.readline()
        if not self.first.startswith("Teleop page: http://localhost:"):
            self.process.kill()  # no page: the command said why (its output, raised below)
            raise RuntimeError(self.first + self.process.communicate(timeout=30)[0])
        self.url = self.first.split()[2]

    def finish(self, timeout=300):
        out, _ = self.process.communicate(timeout=timeout)
        return self.process.returncode, out

    def stop(self):
        if self.process.poll() is None:
            self.process.terminate()
            self.process.communicate(timeout=30)


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
