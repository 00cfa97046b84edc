"""Diagram pictures: Graphviz draws every subsystem and port of a small diagram, and without
Graphviz the diagram's Graphviz text is written instead, with a one-line hint."""

import os
import stat
import xml.etree.ElementTree as ET

import pytest
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Adder, ConstantVectorSource, Gain

from hemg_drake.viz.diagram_svg import diagram_picture, diagram_svg, write_diagram_picture

NAMES = ("stiffness_source", "summing_junction", "doubling_gain")


@pytest.fixture
def diagram():
    builder = DiagramBuilder()
    source = builder.AddNamedSystem("stiffness_source", ConstantVectorSource([1.0]))
    adder = builder.AddNamedSystem("summing_junction", Adder(2, 1))
    gain = builder.AddNamedSystem("doubling_gain", Gain(2.0, 1))
    builder.Connect(source.get_output_port(), adder.get_input_port(0))
    builder.Connect(adder.get_output_port(), gain.get_input_port())
    builder.ExportInput(adder.get_input_port(1), "offset_in")
    builder.ExportOutput(gain.get_output_port(), "doubled_out")
    return builder.Build()


@pytest.fixture
def no_dot(monkeypatch, tmp_path):
    """A PATH on which no Graphviz can be found."""
    empty = tmp_path / "empty_bin"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))


def _fake_dot(monkeypatch, tmp_path, script):
    """Put a shell script named ``dot`` first on PATH (stands in for Graphviz)."""
    folder = tmp_path / "fake_bin"
    folder.mkdir()
    dot = folder / "dot"
    dot.write_text("#!/bin/sh\n" + script + "\n")
    dot.chmod(dot.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("PATH", f"{folder}{os.pathsep}{os.environ['PATH']}")


def _text(svg):
    root = ET.fromstring(svg)  # well-formed XML, or this raises
    assert root.tag.endswith("svg")
    return " ".join(t for t in root.itertext())


def test_svg_names_every_subsystem_and_exported_port(diagram, graphviz):
    text = _text(diagram_svg(diagram))
    for name in NAMES:
        assert name in text
    for port in ("offset_in", "doubled_out"):
        assert port in text


def test_depth_zero_draws_the_diagram_as_one_box(diagram, graphviz):
    text = _text(diagram_svg(diagram, max_depth=0))
    assert "summing_junction" not in text and "offset_in" in text


def test_missing_graphviz_is_a_clear_error(diagram, no_dot):
    with pytest.raises(FileNotFoundError, match="graphviz"):
        diagram_svg(diagram)


@pytest.mark.parametrize("max_depth", [-1, 1.5, True])
def test_bad_depth(diagram, max_depth, tmp_path):
    with pytest.raises(ValueError, match="max_depth"):
        diagram_svg(diagram, max_depth=max_depth)
    with pytest.raises(ValueError, match="max_depth"):
        write_diagram_picture(diagram, tmp_path / "d", max_depth=max_depth)


def test_picture_with_graphviz_is_the_svg(diagram, graphviz, tmp_path):
    path, message = write_diagram_picture(diagram, tmp_path / "diagram")
    assert path == tmp_path / "diagram.svg" and message is None
    text = _text(path.read_text(encoding="utf-8"))
    assert all(name in text for name in NAMES)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["diagram.svg"]  # atomic, no temporary


def test_picture_without_graphviz_is_the_dot_text_and_a_one_line_hint(diagram, no_dot, tmp_path):
    path, message = write_diagram_picture(diagram, tmp_path / "diagram")
    assert path == tmp_path / "diagram.dot"
    text = path.read_text(encoding="utf-8")
    assert text.lstrip().startswith("digraph")
    assert all(name in text for name in NAMES + ("offset_in", "doubled_out"))
    assert "\n" not in message
    assert f"dot -Tsvg {tmp_path / 'diagram.dot'} -o {tmp_path / 'diagram.svg'}" in message
    assert "install graphviz" in message
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_file()) == ["diagram.dot"]


def test_picture_replaces_the_other_kind_left_by_an_earlier_run(diagram, tmp_path, monkeypatch):
    (tmp_path / "diagram.svg").write_text("<svg>an older diagram</svg>")
    monkeypatch.setenv("PATH", str(tmp_path / "nowhere"))
    path, _ = write_diagram_picture(diagram, tmp_path / "diagram.svg")  # the suffix is dropped
    assert path.name == "diagram.dot" and not (tmp_path / "diagram.svg").exists()
    monkeypatch.undo()
    _fake_dot(monkeypatch, tmp_path, 'cat > /dev/null; echo "<svg>drawn</svg>"')
    path, message = write_diagram_picture(diagram, tmp_path / "diagram")
    assert (path.name, message) == ("diagram.svg", None)
    assert path.read_text() == "<svg>drawn</svg>\n"
    assert not (tmp_path / "diagram.dot").exists()


def test_failing_dot_still_writes_the_dot_text(diagram, tmp_path, monkeypatch):
    _fake_dot(monkeypatch, tmp_path, 'cat > /dev/null; echo "syntax error near line 3" >&2; exit 1')
    path, message = write_diagram_picture(diagram, tmp_path / "diagram")
    assert path.name == "diagram.dot" and "digraph" in path.read_text()
    assert "syntax error near line 3" in message and "dot -Tsvg" in message
    assert "install graphviz" not in message  # it is installed; it failed
    with pytest.raises(RuntimeError, match="syntax error"):
        diagram_svg(diagram)


def test_other_suffixes_are_kept_in_the_name(diagram, no_dot, tmp_path):
    path, _ = write_diagram_picture(diagram, tmp_path / "run.v2")
    assert path.name == "run.v2.dot"


def test_notebook_picture_is_the_svg_with_graphviz(diagram, graphviz):
    picture = diagram_picture(diagram)
    assert all(name in _text(picture._repr_svg_()) for name in NAMES)
    assert picture._repr_markdown_() is None and picture.message is None


def test_notebook_picture_without_graphviz_shows_the_text(diagram, no_dot):
    picture = diagram_picture(diagram, max_depth=0)
    assert picture.svg is None and picture._repr_svg_() is None
    markdown = picture._repr_markdown_()
    assert "install graphviz" in markdown
    assert picture.graphviz_text == diagram.GetGraphvizString(max_depth=0)
    assert f"```dot\n{picture.graphviz_text}\n```" in markdown
    assert "install graphviz" in repr(picture)


def test_notebook_picture_when_dot_fails(diagram, tmp_path, monkeypatch):
    _fake_dot(monkeypatch, tmp_path, 'cat > /dev/null; echo "bad things" >&2; exit 3')
    picture = diagram_picture(diagram)
    assert picture.svg is None and "bad things" in picture.message
