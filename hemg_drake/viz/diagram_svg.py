"""A Drake diagram drawn as SVG by Graphviz, every port shown.

``diagram_svg`` needs Graphviz's ``dot``; ``write_diagram_picture`` never fails for want of
it: without ``dot`` it writes the diagram's Graphviz text (``.dot``) and says in one line how
to turn it into the SVG.
"""

import shutil
import subprocess
from pathlib import Path

from hemg_drake.fileio import write_text_atomic

INSTALL_HINT = "install graphviz (apt-get install graphviz)"


def _check_depth(max_depth):
    if isinstance(max_depth, bool) or not isinstance(max_depth, int) or max_depth < 0:
        raise ValueError(f"max_depth must be a non-negative integer, got {max_depth!r}")


def _render_svg(dot, graphviz_text, timeout):
    """SVG text from ``dot -Tsvg``; RuntimeError when dot fails or times out."""
    try:
        result = subprocess.run(
            [dot, "-Tsvg"], input=graphviz_text, capture_output=True, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"dot did not draw the diagram within {timeout} s") from None
    if result.returncode != 0:
        raise RuntimeError(f"dot failed to draw the diagram: {result.stderr.strip()}")
    return result.stdout


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
    RuntimeError
        ``dot`` failed or took longer than ``timeout``.
    """
    _check_depth(max_depth)
    dot = shutil.which("dot")
    if dot is None:
        raise FileNotFoundError(f"Graphviz's 'dot' was not found on PATH; {INSTALL_HINT}")
    return _render_svg(dot, diagram.GetGraphvizString(max_depth=max_depth), timeout)


def write_diagram_picture(diagram, path_without_suffix, *, max_depth=1, timeout=60):
    """Write ``diagram`` as ``<path>.svg``, or as ``<path>.dot`` when Graphviz cannot draw it.

    A picture is never worth failing a run over: without ``dot`` on PATH (or when ``dot``
    fails) the diagram's Graphviz text is written instead, and the returned message says in
    one line how to get the SVG. The file of the other kind left by an earlier run (an old
    ``.svg`` beside a new ``.dot``, or the reverse) is removed, so the folder never shows a
    picture of another run's diagram. Files are written atomically.

    Parameters
    ----------
    diagram : pydrake.systems.framework.Diagram
    path_without_suffix : path-like
        E.g. ``runs/cotter_pin/demonstration_diagram``; a ``.svg`` or ``.dot`` suffix given
        here is dropped (any other suffix is kept as part of the name).
    max_depth : int
        Levels of nested diagrams to expand.
    timeout : float
        Seconds to wait for ``dot``.

    Returns
    -------
    (Path, str or None)
        The file written, and None for an SVG or a one-line message for a ``.dot``.
    """
    _check_depth(max_depth)
    stem = Path(path_without_suffix)
    if stem.suffix.lower() in (".svg", ".dot"):
        stem = stem.with_suffix("")
    svg_path, dot_path = (stem.with_name(stem.name + suffix) for suffix in (".svg", ".dot"))
    graphviz_text = diagram.GetGraphvizString(max_depth=max_depth)
    dot = shutil.which("dot")
    reason = "Graphviz's 'dot' is not on PATH"
    if dot is not None:
        try:
            svg = _render_svg(dot, graphviz_text, timeout)
        except (RuntimeError, OSError) as error:
            reason = str(error).splitlines()[0] if str(error) else "dot failed"
        else:
            write_text_atomic(svg_path, svg)
            dot_path.unlink(missing_ok=True)
            return svg_path, None
    write_text_atomic(dot_path, graphviz_text)
    svg_path.unlink(missing_ok=True)
    how = f"dot -Tsvg {dot_path} -o {svg_path}"
    if dot is None:
        how = f"{INSTALL_HINT}, then run: {how}"
    else:
        how = f"run: {how}"
    return dot_path, f"{reason}: wrote {dot_path} instead of the SVG; to draw it, {how}"


class DiagramPicture:
    """A diagram for a notebook: shown as SVG when Graphviz draws it, else as its text.

    Jupyter shows the SVG (``_repr_svg_``); without ``dot`` it shows the one-line hint and
    the Graphviz text instead (``_repr_markdown_``), so a notebook runs on any machine.

    Attributes
    ----------
    svg : str or None
        The SVG document, or None when Graphviz could not draw it.
    graphviz_text : str
        ``diagram.GetGraphvizString(max_depth=...)``.
    message : str or None
        Why there is no SVG, and how to get one; None with an SVG.
    """

    def __init__(self, svg, graphviz_text, message):
        self.svg, self.graphviz_text, self.message = svg, graphviz_text, message

    def _repr_svg_(self):
        return self.svg

    def _repr_markdown_(self):
        if self.svg is not None:
            return None
        return f"{self.message}\n\n```dot\n{self.graphviz_text}\n```\n"

    def __repr__(self):
        return "DiagramPicture(SVG)" if self.svg is not None else f"DiagramPicture({self.message})"


def diagram_picture(diagram, *, max_depth=1, timeout=60):
    """``diagram`` as a :class:`DiagramPicture`: SVG with Graphviz, its text without.

    Parameters
    ----------
    diagram : pydrake.systems.framework.Diagram
    max_depth : int
        Levels of nested diagrams to expand.
    timeout : float
        Seconds to wait for ``dot``.
    """
    _check_depth(max_depth)
    graphviz_text = diagram.GetGraphvizString(max_depth=max_depth)
    dot = shutil.which("dot")
    if dot is None:
        return DiagramPicture(None, graphviz_text,
                              f"Graphviz's 'dot' is not on PATH: {INSTALL_HINT} to see the "
                              "diagram drawn; its Graphviz text follows")
    try:
        return DiagramPicture(_render_svg(dot, graphviz_text, timeout), graphviz_text, None)
    except (RuntimeError, OSError) as error:
        first = str(error).splitlines()[0] if str(error) else "dot failed"
        return DiagramPicture(None, graphviz_text, f"{first}; the diagram's Graphviz text follows")
