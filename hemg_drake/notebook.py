"""Small helpers for the walkthroughs in ``notebooks/``: the scale switch, the shipped
scenarios, inline replays, and stripping outputs before a commit.

The test suite executes every notebook with ``HEMG_DRAKE_NOTEBOOK_SCALE=small`` so that each
runs in seconds; a user who opens one gets the full scale::

    scenario = load_scenario(scenario_file("cotter_pin"))
    duration = at_scale(full=scenario.duration, small=2.0)
    HTML(replay_iframe("replay.html"))   # from IPython.display
"""

import html
import os
from pathlib import Path

from hemg_drake.fileio import write_text_atomic
from hemg_drake.scenario import shipped_scenario

SCALE_VARIABLE = "HEMG_DRAKE_NOTEBOOK_SCALE"
SCALES = ("full", "small")


def notebook_scale():
    """The scale the notebooks run at: ``"full"`` (default) or ``"small"``.

    Read from the environment variable ``HEMG_DRAKE_NOTEBOOK_SCALE``.

    Raises
    ------
    ValueError
        The variable holds something other than ``full`` or ``small``.
    """
    scale = os.environ.get(SCALE_VARIABLE, "full").strip().lower() or "full"
    if scale not in SCALES:
        raise ValueError(f"{SCALE_VARIABLE} must be one of {SCALES}, got {scale!r}")
    return scale


def at_scale(*, full, small):
    """``small`` when the notebooks run at small scale, else ``full``."""
    return small if notebook_scale() == "small" else full


def scenario_file(name):
    """Path of the shipped scenario ``name`` (``"cotter_pin"``, ``"drawing"``), wherever the
    notebook runs (the scenarios are package data).

    Raises
    ------
    FileNotFoundError
        No such scenario; the message lists those there are.
    """
    return shipped_scenario(name)


def replay_iframe(replay, *, height=480):
    """An ``<iframe>`` showing an HTML replay inline, its page embedded through ``srcdoc``.

    The replay (``ReplayRecorder.stop_and_export``) is self-contained, so the frame needs no
    server and no network; wrap the result in ``IPython.display.HTML`` to show it.

    Parameters
    ----------
    replay : str or Path
        The replay's HTML file.
    height : int
        Frame height in pixels (the width fills the cell).

    Returns
    -------
    str
        A ``<div>`` holding the ``<iframe>``.
    """
    path = Path(replay)
    if not path.is_file():
        raise FileNotFoundError(f"replay file not found: {path}")
    if isinstance(height, bool) or not isinstance(height, int) or height <= 0:
        raise ValueError(f"height must be a positive number of pixels, got {height!r}")
    page = path.read_text(encoding="utf-8")
    if "<html" not in page[:1000].lower():
        raise ValueError(f"{path}: not an HTML page")
    # Inside a <div>: IPython's HTML() warns about markup that starts with "<iframe".
    return (
        f'<div><iframe srcdoc="{html.escape(page, quote=True)}" width="100%" '
        f'height="{height}" style="border: none"></iframe></div>'
    )


def strip_outputs(*paths):
    """Clear the outputs and execution counts of notebooks in place (atomically).

    Notebooks are committed without outputs; run this before committing an edited one.
    Needs ``nbformat`` (in the ``dev`` extra).

    Parameters
    ----------
    *paths : str or Path
        ``.ipynb`` files.
    """
    import nbformat

    for path in map(Path, paths):
        if not path.is_file():
            raise FileNotFoundError(f"notebook not found: {path}")
        try:
            notebook = nbformat.read(path, as_version=4)
        except Exception as error:  # nbformat raises several unrelated types
            raise ValueError(f"{path}: not a readable notebook ({error})") from None
        for cell in notebook.cells:
            if cell.cell_type == "code":
                cell.outputs, cell.execution_count = [], None
        write_text_atomic(path, nbformat.writes(notebook) + "\n")
