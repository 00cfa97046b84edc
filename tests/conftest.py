"""Shared test settings: headless plots, the path to the published facts (docs/facts)."""

import os
import shutil
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


def pytest_collection_modifyitems(config, items):
    """The full fault-injection counts (marked ``deep``) run in .ci/run's own step
    (HEMG_DRAKE_DEEP_TESTS=1), so that ``make test`` keeps to minutes; it runs a seeded
    subset of each."""
    if os.environ.get("HEMG_DRAKE_DEEP_TESTS") == "1":
        return
    skip = pytest.mark.skip(reason="the full fault counts: HEMG_DRAKE_DEEP_TESTS=1 (.ci/run)")
    for item in items:
        if "deep" in item.keywords:
            item.add_marker(skip)


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


@pytest.fixture
def synthetic_run(tmp_path):
    """A run folder with a finished demonstrate stage of two synthetic demonstrations (no
    simulation: straight lines, constant gain)."""
    import numpy as np

    from hemg_drake.learning.demos import Demonstration, save_dataset
    from hemg_drake.run_folder import RunFolder
    from hemg_drake.scenario import load_scenario, shipped_scenario

    run = tmp_path / "run"
    scenario = load_scenario(shipped_scenario("cotter_pin"))
    demos = []
    for c in range(2):
        t = np.arange(0.0, 1.0 + 1e-9, 0.01)
        line = np.column_stack([0.6 + 0 * t, -0.8 + 0 * t, 0.1 + 0.05 * t + 0.001 * c])
        zeros, e = np.zeros(len(t)), np.arange(200) / 200.0
        demos.append(Demonstration(
            seed=c + 1, time=t, p_WE=line, v_WE=np.gradient(line, t, axis=0), p_MS=line,
            p_WE_desired=line, envelope=zeros, activation=zeros, gain=zeros + 50.0,
            f_WE=np.zeros((len(t), 3)), emg_time=e, emg=np.zeros((200, 8)),
            muscle_activation=np.zeros(200),
        ))  # fmt: skip
    folder = RunFolder(run, create=True)
    save_dataset(folder.dataset, demos, {"scenario": scenario.to_yaml(), "task": "cotter_pin"})
    folder.finish("demonstrate", [folder.dataset])
    return run
