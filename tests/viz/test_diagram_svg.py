"""Diagram pictures: Graphviz draws every subsystem and port of a small diagram."""

import xml.etree.ElementTree as ET

import pytest
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Adder, ConstantVectorSource, Gain

from hemg_drake.viz.diagram_svg import diagram_svg

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


def _text(svg):
    root = ET.fromstring(svg)  # well-formed XML, or this raises
    assert root.tag.endswith("svg")
    return " ".join(t for t in root.itertext())


def test_svg_names_every_subsystem_and_exported_port(diagram, graphviz):
    text = _text(diagram_svg(diagram))
    for name in ("stiffness_source", "summing_junction", "doubling_gain"):
        assert name in text
    for port in ("offset_in", "doubled_out"):
        assert port in text


def test_depth_zero_draws_the_diagram_as_one_box(diagram, graphviz):
    text = _text(diagram_svg(diagram, max_depth=0))
    assert "summing_junction" not in text and "offset_in" in text


def test_missing_graphviz_is_a_clear_error(diagram, monkeypatch):
    monkeypatch.setenv("PATH", "/nonexistent")
    with pytest.raises(FileNotFoundError, match="graphviz"):
        diagram_svg(diagram)


@pytest.mark.parametrize("max_depth", [-1, 1.5, True])
def test_bad_depth(diagram, max_depth):
    with pytest.raises(ValueError, match="max_depth"):
        diagram_svg(diagram, max_depth=max_depth)
