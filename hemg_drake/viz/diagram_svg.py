"""A Drake diagram drawn as SVG by Graphviz, every port shown."""

import shutil
import subprocess


def diagram_svg(diagram, *, max_depth=1, timeout=60):
    """Draw ``diagram`` with Graphviz ``dot`` and return the SVG text.

    Parameters
    ----------
    diagram : pydrake.systems.framework.Diagram
    max_depth : int
        Levels of nested diagrams to expand (1: the top level's subsystems and their ports).
    timeout : float
        Seconds to wait for ``dot``.

    Returns
    -------
    str
        An SVG document; show it with ``IPython.display.SVG(data=...)`` or write it with
        ``hemg_drake.fileio.write_text_atomic``.

    Raises
    ------
    FileNotFoundError
        Graphviz is not installed (Debian: ``apt-get install graphviz``).
    """
    if isinstance(max_depth, bool) or not isinstance(max_depth, int) or max_depth < 0:
        raise ValueError(f"max_depth must be a non-negative integer, got {max_depth!r}")
    dot = shutil.which("dot")
    if dot is None:
        raise FileNotFoundError(
            "Graphviz's 'dot' was not found on PATH; install graphviz (apt-get install graphviz)"
        )
    result = subprocess.run(
        [dot, "-Tsvg"],
        input=diagram.GetGraphvizString(max_depth=max_depth),
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    if result.returncode != 0:
        raise RuntimeError(f"dot failed to draw the diagram: {result.stderr.strip()}")
    return result.stdout
