"""The live Meshcat page in headless Chromium, driven through the DevTools protocol: test
tooling (tests/teleop/test_browser.py, benchmarks/bench_teleop_browser.py), not runtime."""

import contextlib
import os
import signal
import subprocess
import time

from hemg_drake.viz.screenshot import QUIET_FLAGS, WEBGL_FLAGS, find_chromium, remove_profile


class HeadlessPage:
    """The live Meshcat page in headless Chromium, driven through the DevTools protocol.

    For tests, screenshots and latency checks without a person: ``press(code)`` sends a
    real key press to the page (as a keyboard would), ``screenshot()`` returns a PNG.
    Needs Debian's ``chromium`` and ``websocket-client`` (the dev extra). Use as a
    context manager; the browser process is ended on exit.

    Parameters
    ----------
    url : str, the page (``meshcat.web_url()``).
    size : (int, int), window size in pixels.
    timeout : float, seconds to wait for Chromium to start.
    """

    def __init__(self, url, *, size=(1280, 800), timeout=60.0):
        import select
        import tempfile

        import websocket


        chromium = find_chromium()
        if chromium is None:
            raise FileNotFoundError(
                "chromium not found on PATH: install it (apt-get install chromium)"
            )
        self._profile = tempfile.mkdtemp(prefix="hemg-teleop-chromium-")
        command = [
            chromium, *WEBGL_FLAGS, *QUIET_FLAGS,
            f"--user-data-dir={self._profile}", f"--window-size={size[0]},{size[1]}",
            "--remote-debugging-port=0", "--remote-allow-origins=*", url,
        ]  # fmt: skip
        # Its own process group: Chromium's helpers (GPU, crashpad) outlive the main process
        # and keep writing into the profile, so close() ends the whole group.
        self.process = subprocess.Popen(
            command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            text=True, start_new_session=True,
        )  # fmt: skip
        deadline = time.monotonic() + timeout
        browser_url = None
        try:
            while browser_url is None:
                left = deadline - time.monotonic()
                if left <= 0 or self.process.poll() is not None:
                    raise RuntimeError("headless Chromium did not start its DevTools endpoint")
                ready, _, _ = select.select([self.process.stderr], [], [], left)
                if ready:
                    line = self.process.stderr.readline()
                    if line.startswith("DevTools listening on "):
                        browser_url = line.split(" on ", 1)[1].strip()
            # The first page target is the one showing ``url``.
            self._ws = websocket.create_connection(browser_url, timeout=timeout)
            self._id = 0
            targets = self._call("Target.getTargets")["targetInfos"]
            page = next(t for t in targets if t["type"] == "page")
            session = self._call("Target.attachToTarget", targetId=page["targetId"], flatten=True)
            self._session = session["sessionId"]
        except BaseException:
            self.close()
            raise

    def _call(self, method, session=None, **params):
        import json

        self._id += 1
        message = {"id": self._id, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        self._ws.send(json.dumps(message))
        while True:
            reply = json.loads(self._ws.recv())
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"DevTools {method}: {reply['error']}")
                return reply.get("result", {})

    def page(self, method, **params):
        """Call a DevTools method on the page (e.g. ``Runtime.evaluate``)."""
        return self._call(method, session=self._session, **params)

    def press(self, code, *, shift=False):
        """Press and release the key ``code`` (a KeyboardEvent.code, e.g. "ArrowRight")."""
        for kind in ("keyDown", "keyUp"):
            self.key(kind, code, shift=shift)

    def key(self, kind, code, *, shift=False):
        """One key event: ``kind`` "keyDown" or "keyUp" (a key held between the two)."""
        key = code[3:].lower() if code.startswith("Key") else code
        self.page("Input.dispatchKeyEvent", type=kind, code=code, key=key,
                  modifiers=8 if shift else 0)  # fmt: skip

    def evaluate(self, expression):
        """The value of a javascript expression in the page."""
        result = self.page("Runtime.evaluate", expression=expression, returnByValue=True)
        return result.get("result", {}).get("value")

    def screenshot(self):
        """A PNG of the page (bytes)."""
        import base64

        return base64.b64decode(self.page("Page.captureScreenshot", format="png")["data"])

    def close(self):
        with contextlib.suppress(Exception):
            self._ws.close()
        self._signal_group(signal.SIGTERM)
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self._signal_group(signal.SIGKILL)  # helpers left behind
        with contextlib.suppress(Exception):
            self.process.stderr.close()
        remove_profile(self._profile)

    def _signal_group(self, signum):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.process.pid, signum)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
