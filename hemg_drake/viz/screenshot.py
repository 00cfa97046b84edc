"""Render an HTML replay to a PNG with headless Chromium (Debian package ``chromium``)."""

import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

from hemg_drake.fileio import write_bytes_atomic

# Meshcat needs WebGL; headless Chromium only has it through SwiftShader (software).
# Without these flags the screenshot is a blank page.
WEBGL_FLAGS = ("--headless=new", "--use-angle=swiftshader", "--enable-unsafe-swiftshader")
# A throw-away profile that talks to no one (also the live teleop page's in the tests,
# tests/tooling/headless_page.py).
QUIET_FLAGS = (
    "--no-sandbox",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
)
# No name resolves: a replay must render from the file alone.
_OFFLINE_FLAGS = ("--host-resolver-rules=MAP * ~NOTFOUND",)


def remove_profile(path):
    """Delete a Chromium profile folder; a helper process still flushing as it dies can
    refill it for a moment, so retry, then leave what stays to the OS."""
    for _ in range(20):
        shutil.rmtree(path, ignore_errors=True)
        if not os.path.exists(path):
            return
        time.sleep(0.05)


def find_chromium():
    """Path of the Chromium executable, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


def render_html_to_png(html_path, png_path, *, size=(800, 600), budget_ms=10000, timeout=120):
    """Load ``html_path`` in headless Chromium and save a screenshot to ``png_path``.

    Parameters
    ----------
    html_path, png_path : path-like.
    size : (int, int), window width and height in pixels.
    budget_ms : int, virtual time the page gets to load and draw before the shot.
    timeout : float, seconds of wall time before giving up.

    Returns
    -------
    Path, ``png_path``.

    Raises
    ------
    FileNotFoundError
        No ``html_path``, or no Chromium (install the Debian package ``chromium``).
    RuntimeError
        Chromium failed or wrote no picture.
    """
    html_path = Path(html_path).resolve()
    png_path = Path(png_path).resolve()
    if not html_path.is_file():
        raise FileNotFoundError(f"HTML file not found: {html_path}")
    width, height = (int(s) for s in size)
    if width <= 0 or height <= 0:
        raise ValueError(f"size must be two positive integers, got {size}")
    chromium = find_chromium()
    if chromium is None:
        raise FileNotFoundError("chromium not found on PATH: install it (apt-get install chromium)")
    profile = tempfile.mkdtemp(prefix="hemg-chromium-")
    try:
        # Chromium writes the shot into the temporary profile; it is then copied atomically.
        shot = Path(profile) / "shot.png"
        command = [
            chromium,
            *WEBGL_FLAGS,
            *QUIET_FLAGS,
            *_OFFLINE_FLAGS,
            f"--user-data-dir={profile}/user-data",
            f"--window-size={width},{height}",
            f"--virtual-time-budget={int(budget_ms)}",
            f"--screenshot={shot}",
            html_path.as_uri(),
        ]
        result = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
        if result.returncode != 0 or not shot.is_file():
            tail = "\n".join(result.stderr.strip().splitlines()[-5:])
            raise RuntimeError(
                f"chromium could not render {html_path} (exit {result.returncode}):\n{tail}"
            )
        write_bytes_atomic(png_path, shot.read_bytes())
    finally:
        remove_profile(profile)
    return png_path
