"""Notebook helpers: the scale switch and the inline replay frame."""

import html.parser

import pytest

from hemg_drake.notebook import (
    SCALE_VARIABLE,
    at_scale,
    notebook_scale,
    replay_iframe,
    scenario_file,
    strip_outputs,
)
from hemg_drake.scenario import load_scenario


@pytest.mark.parametrize(
    "value, expected", [(None, "full"), ("", "full"), ("full", "full"), (" Small ", "small")]
)
def test_scale_is_read_from_the_environment(monkeypatch, value, expected):
    if value is None:
        monkeypatch.delenv(SCALE_VARIABLE, raising=False)
    else:
        monkeypatch.setenv(SCALE_VARIABLE, value)
    assert notebook_scale() == expected
    assert at_scale(full=8.0, small=1.0) == (1.0 if expected == "small" else 8.0)


def test_unknown_scale_is_a_clear_error(monkeypatch):
    monkeypatch.setenv(SCALE_VARIABLE, "tiny")
    with pytest.raises(ValueError, match=f"{SCALE_VARIABLE} must be one of"):
        at_scale(full=1, small=0)


class _Frames(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.frames = []

    def handle_starttag(self, tag, attrs):
        if tag == "iframe":
            self.frames.append(dict(attrs))


def test_replay_iframe_embeds_the_page_exactly(tmp_path):
    # Quotes, ampersands and markup must survive the attribute round trip unchanged.
    page = '<!DOCTYPE html><html><body><script>let s = "a&b" + \'<c>\';</script></body></html>'
    replay = tmp_path / "replay.html"
    replay.write_text(page, encoding="utf-8")
    parser = _Frames()
    parser.feed(replay_iframe(replay, height=300))
    (frame,) = parser.frames
    assert frame["srcdoc"] == page
    assert frame["height"] == "300"


def test_replay_iframe_bad_input(tmp_path):
    with pytest.raises(FileNotFoundError, match="replay file not found"):
        replay_iframe(tmp_path / "missing.html")
    text = tmp_path / "notes.txt"
    text.write_text("no page here", encoding="utf-8")
    with pytest.raises(ValueError, match="not an HTML page"):
        replay_iframe(text)
    page = tmp_path / "page.html"
    page.write_text("<html></html>", encoding="utf-8")
    with pytest.raises(ValueError, match="height"):
        replay_iframe(page, height=0)


def test_scenario_file_finds_the_repository_scenarios():
    path = scenario_file("cotter_pin")
    assert path.is_file() and path.parent.name == "scenarios"
    assert load_scenario(path).task == "cotter_pin"


def test_unknown_scenario_lists_the_known_ones():
    with pytest.raises(FileNotFoundError, match="no shipped scenario named 'juggling'.*cotter_pin"):
        scenario_file("juggling")


def test_strip_outputs_clears_outputs_and_counts_only(tmp_path):
    nbformat = pytest.importorskip("nbformat")
    notebook = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_markdown_cell("# title"),
        nbformat.v4.new_code_cell("1 + 1", execution_count=3, outputs=[
            nbformat.v4.new_output("execute_result", {"text/plain": "2"}, execution_count=3)
        ]),
    ])
    path = tmp_path / "n.ipynb"
    nbformat.write(notebook, path)
    strip_outputs(path)
    stripped = nbformat.read(path, as_version=4)
    assert stripped.cells[1].outputs == [] and stripped.cells[1].execution_count is None
    assert [c.source for c in stripped.cells] == ["# title", "1 + 1"]


def test_strip_outputs_bad_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="notebook not found"):
        strip_outputs(tmp_path / "missing.ipynb")
    broken = tmp_path / "broken.ipynb"
    broken.write_text("{not json", encoding="utf-8")
    with pytest.raises(ValueError, match="broken.ipynb: not a readable notebook"):
        strip_outputs(broken)
