"""Every notebook in notebooks/ runs headless, top to bottom, at small scale, and is committed
without outputs.

Each runs in a fresh kernel of this Python (the project's virtualenv) inside a temporary
working directory, so nothing it writes lands in the repository; the kernel is shut down
whatever happens, which also stops any Meshcat server it started. Graphviz is not needed:
without it the diagrams are shown as their Graphviz text (one notebook is run so here).
"""

import os
import shutil
import sys
from pathlib import Path

import nbformat
import pytest
from jupyter_client import KernelManager
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError

from hemg_drake.notebook import SCALE_VARIABLE

NOTEBOOKS_DIR = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(NOTEBOOKS_DIR.glob("*.ipynb"))
CELL_TIMEOUT = 180  # s; the whole set takes well under 3 minutes
# Appended to the executed copy: where the kernel ran, with which settings.
PROBE = "import os, sys; print(sys.prefix); print(os.environ['{}']); print(os.getcwd())"


def test_notebooks_folder_holds_notebooks():
    assert NOTEBOOKS, f"no notebook found in {NOTEBOOKS_DIR}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda path: path.name)
def test_committed_without_outputs(path):
    notebook = nbformat.read(path, as_version=4)
    nbformat.validate(notebook)
    assert notebook.metadata.kernelspec.name == "python3"
    for index, cell in enumerate(notebook.cells):
        if cell.cell_type == "code":
            assert cell.outputs == [], f"{path.name}: cell {index} has outputs; strip them"
            assert cell.execution_count is None, f"{path.name}: cell {index} has a count"


def _execute(notebook, name, workdir):
    """Run ``notebook`` in a fresh kernel in ``workdir``; fail the test on a cell's error.

    Returns the executed notebook's probe output: the kernel's sys.prefix, scale and cwd.
    """
    notebook.cells.append(nbformat.v4.new_code_cell(PROBE.format(SCALE_VARIABLE)))
    manager = KernelManager(kernel_name="python3")
    client = NotebookClient(
        notebook,
        km=manager,
        timeout=CELL_TIMEOUT,
        resources={"metadata": {"path": str(workdir)}},
    )
    try:
        with client.setup_kernel():
            kernel_pid = manager.provisioner.pid
            client.execute()
    except CellExecutionError as error:
        pytest.fail(f"{name}: a cell failed:\n{error}", pytrace=False)
    finally:
        if client.kc is not None:
            client.kc.stop_channels()
        if manager.has_kernel:
            manager.shutdown_kernel(now=True)
        assert not manager.is_alive()
    with pytest.raises(ProcessLookupError):
        os.kill(kernel_pid, 0)  # the kernel process, and any Meshcat server in it, is gone
    outputs = notebook.cells[-1].outputs
    return "".join(output.get("text", "") for output in outputs).split("\n")[:3]


@pytest.fixture
def small_scale(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.setenv(SCALE_VARIABLE, "small")


def _diagram_outputs(notebook):
    """The display data of each cell that shows a diagram (``diagram_picture``)."""
    return [
        output.get("data", {})
        for cell in notebook.cells
        if cell.cell_type == "code" and "diagram_picture(" in cell.source
        for output in cell.outputs
        if output.output_type in ("execute_result", "display_data")
    ]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda path: path.name)
def test_notebook_runs_top_to_bottom(path, tmp_path, small_scale):
    # With or without Graphviz: the diagrams are drawn as SVG, or shown as their text.
    before = sorted(NOTEBOOKS_DIR.iterdir())
    notebook = nbformat.read(path, as_version=4)
    probe = _execute(notebook, path.name, tmp_path)
    assert probe == [sys.prefix, "small", str(tmp_path)]
    assert sorted(NOTEBOOKS_DIR.iterdir()) == before, "the notebook wrote into notebooks/"
    shown = _diagram_outputs(notebook)
    assert shown, f"{path.name}: no diagram shown"
    kind = "image/svg+xml" if shutil.which("dot") else "text/markdown"
    assert all(kind in data for data in shown), [sorted(data) for data in shown]


@pytest.fixture
def no_graphviz(monkeypatch, tmp_path):
    """A PATH holding every program of this one but Graphviz's ``dot``."""
    folder = tmp_path / "bin_without_dot"
    folder.mkdir()
    for directory in os.environ.get("PATH", "").split(os.pathsep):
        if not os.path.isdir(directory):
            continue
        for entry in os.scandir(directory):
            if entry.name != "dot" and not (folder / entry.name).exists():
                (folder / entry.name).symlink_to(entry.path)
    monkeypatch.setenv("PATH", str(folder))
    assert shutil.which("dot") is None


def test_a_notebook_runs_without_graphviz_and_shows_the_diagram_as_text(
    tmp_path, small_scale, no_graphviz
):  # fmt: skip
    path = NOTEBOOKS_DIR / "01_emg_to_stiffness.ipynb"
    notebook = nbformat.read(path, as_version=4)
    _execute(notebook, path.name, tmp_path)
    (shown,) = _diagram_outputs(notebook)
    assert "image/svg+xml" not in shown
    assert "Graphviz's 'dot' is not on PATH" in shown["text/markdown"]
    assert "digraph" in shown["text/markdown"]



def test_a_failing_cell_fails_with_its_error(tmp_path, small_scale):
    notebook = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_code_cell("x = 1"),
        nbformat.v4.new_code_cell("raise ValueError('gain must be positive, got -3')"),
        nbformat.v4.new_code_cell("print('never reached')"),
    ])
    with pytest.raises(pytest.fail.Exception, match=r"bad.ipynb: a cell failed(.|\n)*-3"):
        _execute(notebook, "bad.ipynb", tmp_path)
