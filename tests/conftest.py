"""Shared test settings: headless plots, the path to the published facts (docs/facts)."""

import os
import shutil
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

REPO = Path(__file__).resolve().parents[1]
# The published test vectors ship with the repository (docs/facts.md names their sources).
FACTS = REPO / "docs" / "facts"


@pytest.fixture
def facts_dir():
    if not FACTS.is_dir():
        pytest.fail(f"the published facts are not at {FACTS}")
    return FACTS



def _missing_tool(name, package):
    """Skip a test whose tool is missing; under CI (which installs it) fail instead."""
    if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
        pytest.fail(f"{name} is missing under CI: .ci/run must install Debian's {package}")
    pytest.skip(f"{name} not installed (apt-get install {package})")


@pytest.fixture
def chromium():
    """Headless Chromium renders the HTML replays."""
    from hemg_drake.viz.screenshot import find_chromium

    if find_chromium() is None:
        _missing_tool("chromium", "chromium")


@pytest.fixture
def graphviz():
    """Graphviz's dot draws the diagram pictures."""
    if shutil.which("dot") is None:
        _missing_tool("dot", "graphviz")


@pytest.fixture
def run_cli(capsys):
    """``run_cli(argv)``: (exit status, stdout, stderr) of ``hemg-drake argv``, argparse's
    exits included."""
    from hemg_drake.cli import main

    def run(argv):
        try:
            code = main(argv)
        except SystemExit as exit:
            code = exit.code
        captured = capsys.readouterr()
        return code, captured.out, captured.err

    return run
