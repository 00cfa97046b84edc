"""The layering flows one way (issue 13): read from the sources' import statements and calls."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "hemg_drake"


def _imports(path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return names, tree


def _calls(tree):
    return {
        node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
    }


def test_the_model_does_not_import_the_reproduction():
    names, _ = _imports(PACKAGE / "learning" / "hsmm.py")
    assert "hemg_drake.learning.reproduce" not in names


@pytest.mark.parametrize("path", sorted((PACKAGE / "diagrams").glob("*.py")), ids=lambda p: p.name)
def test_diagrams_neither_save_datasets_nor_plot(path):
    names, tree = _imports(path)
    assert not any(name.startswith(("matplotlib", "hemg_drake.viz.figures")) for name in names)
    assert not {"save_dataset", "save_figure", "savefig", "save_npz_atomic"} & _calls(tree)


@pytest.mark.parametrize("path", sorted((PACKAGE / "tasks").glob("*.py")), ids=lambda p: p.name)
def test_tasks_hold_no_diagram_builders(path):
    names, tree = _imports(path)
    assert not any(name.startswith("hemg_drake.diagrams") for name in names)
    assert "Build" not in _calls(tree) and "DiagramBuilder" not in _calls(tree)
