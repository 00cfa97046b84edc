"""Wall-clock time to execute each notebook top to bottom, at small and at full scale.

Each notebook runs in a fresh kernel of this Python, in a temporary working directory, as
the test suite runs them (``tests/test_notebooks.py``, small scale). Prints one line per
notebook and scale, and the totals; the issue's budget is 3 minutes for all of them.
"""

import os
import tempfile
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

from hemg_drake.notebook import SCALE_VARIABLE

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


def execute(path, scale):
    """Seconds to execute the notebook at ``path`` at ``scale``."""
    os.environ[SCALE_VARIABLE] = scale  # inherited by the kernel
    notebook = nbformat.read(path, as_version=4)
    with tempfile.TemporaryDirectory() as workdir:
        client = NotebookClient(
            notebook, kernel_name="python3", timeout=600, resources={"metadata": {"path": workdir}}
        )
        start = time.perf_counter()
        client.execute()  # starts and shuts down its own kernel
        return time.perf_counter() - start


if __name__ == "__main__":
    os.environ.setdefault("MPLBACKEND", "Agg")
    for scale in ("small", "full"):
        total = 0.0
        for path in NOTEBOOKS:
            seconds = execute(path, scale)
            total += seconds
            print(f"{path.name:40s} {scale:5s} {seconds:6.1f} s")
        print(f"{'all notebooks':40s} {scale:5s} {total:6.1f} s (budget 180 s)")
