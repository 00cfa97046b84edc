"""The README's picture of the teleop page: a drawing take driven to its end by the
closed-loop key driver (:func:`tooling.page_driver.draw_strokes`), pictured once the take has
ended and the page shows its score against the template. Not a test: run by hand.

Headless Chromium renders in software, where the page halves its pixel ratio; the picture is
rendered at full resolution, as a browser with a GPU shows it.

    .venv/bin/python tests/tooling/page_picture.py docs/img/teleop_page.png
"""

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))

from hemg_drake.fileio import write_bytes_atomic  # noqa: E402
from tooling.headless_page import HeadlessPage  # noqa: E402
from tooling.page_driver import PageDriver, draw_strokes  # noqa: E402
from tooling.teleop_page import Command, controls_ready, wait_for  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("png", help="where to write the picture")
    args = parser.parse_args()
    out_dir = Path(tempfile.mkdtemp(prefix="hemg-page-picture-")) / "run"
    command = Command("drawing", "--out", str(out_dir), "--port", "0", "--no-replay")
    try:
        with HeadlessPage(command.url, size=(1280, 800)) as page:
            wait_for(page, "waiting", timeout=300.0)
            controls_ready(page)
            page.press("Enter")
            wait_for(page, "recording")
            driver = PageDriver(page)
            driver.wait_take_time(0.3)
            draw_strokes(driver, depth=2.5e-3, hold=4e-3, activation=0.5)
            page.press("Escape")
            wait_for(page, "ended", timeout=300.0)
            page.evaluate("viewer.renderer.setPixelRatio(1); viewer.set_dirty(); 0")
            time.sleep(2.0)
            write_bytes_atomic(args.png, page.screenshot())
            print(page.evaluate("document.getElementById('hemg-hint').textContent"))
            page.press("KeyD")  # nothing is kept
        command.finish(timeout=120)  # the page closed before the next take: the command ends
    finally:
        command.stop()


if __name__ == "__main__":
    main()
