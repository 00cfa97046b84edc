"""The layering flows one way (issues 13 and 22), read from the sources' import statements
and calls, and no module holds more than one job's worth of lines.

Layers, lowest first; a module may import its own layer and those below, never above:

0. configs and base helpers: the ``config.py`` of each package, ``config_fields``,
   ``_validate``, ``fileio``, ``folder_lock``, ``folder_versions``,
   ``yaml_schema``;
1. systems: ``emg``, ``control``, ``teleop``, ``learning``, ``assist``, ``robots``, ``tasks``;
2. station and diagrams: ``diagrams``, the ``scenario`` that composes the configs for the
   builders, ``placements``;
3. analysis of logs: ``analysis``, ``evaluation``, ``tasks.metrics``;
4. visualisation: ``viz``;
5. applications: ``pipeline``, ``demo``, ``run_folder``, ``sweep``, ``cli`` and its ``commands``,
   ``teleop_session``, ``notebook``.
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "hemg_drake"
MAX_LINES = 500

LAYERS = ("configs", "systems", "station", "analysis", "viz", "applications")
# Module name prefixes (without "hemg_drake.") and their layer; the longest prefix wins.
PLACES = {
    "": "configs",  # hemg_drake/__init__.py
    "config_fields": "configs",
    "_validate": "configs",
    "fileio": "configs",
    "folder_lock": "configs",
    "folder_versions": "configs",
    "yaml_schema": "configs",
    "emg": "systems",
    "control": "systems",
    "teleop": "systems",
    "learning": "systems",
    "assist": "systems",
    "robots": "systems",
    "tasks": "systems",
    # A task plan is data (numpy only); a config may check a written-out plan with it.
    "tasks.plan": "configs",
    "diagrams": "station",
    "scenario": "station",
    "placements": "station",
    "analysis": "analysis",
    "evaluation": "analysis",
    "tasks.metrics": "analysis",
    "viz": "viz",
    "pipeline": "applications",
    "demo": "applications",
    "run_folder": "applications",
    "sweep": "applications",
    "cli": "applications",
    "commands": "applications",
    "teleop_session": "applications",
    "teleop_takes": "applications",
    "notebook": "applications",
}
# Upward imports still to be removed. Shrink only: an entry that no longer happens fails,
# so that it is deleted here. (Empty since the diagrams stopped taking a replay recorder:
# visualisation comes from ApplyVisualizationConfig, issue 22 section 2.)
KNOWN_UPWARD = set()
# Modules over MAX_LINES on main (under hemg_drake/ by their path there, tests as tests/...),
# with their line counts then: they may only shrink, and an entry at or under MAX_LINES
# fails, so that it is deleted here.
KNOWN_LONG = {}


def module_name(path):
    """``hemg_drake.a.b`` of a source file under PACKAGE (a package's ``__init__``: its own)."""
    parts = ("hemg_drake", *path.relative_to(PACKAGE).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def layer(module):
    """The layer index of a ``hemg_drake`` module (``config`` modules: 0); KeyError if none."""
    rest = module.removeprefix("hemg_drake").removeprefix(".")
    parts = rest.split(".") if rest else []
    if parts and parts[-1] == "config":
        return 0
    for n in range(len(parts), -1, -1):
        place = PLACES.get(".".join(parts[:n]))
        if place is not None:
            return LAYERS.index(place)
    raise KeyError(f"{module} has no layer: add its package to PLACES in {__file__}")


def _imports(path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return names, tree


def imported_modules(source, module):
    """The ``hemg_drake`` modules that ``source`` (the text of ``module``) imports, anywhere
    in it (function-local imports too); ``from hemg_drake.x import y`` counts ``x.y`` when
    y is a module, else ``x``."""
    tree = ast.parse(source)
    package = module if _is_package(module) else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the module's package up
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            for alias in node.names:
                child = f"{base}.{alias.name}"
                found.add(child if _exists(child) else base)
    return {name for name in found if name == "hemg_drake" or name.startswith("hemg_drake.")}


def _path(module):
    return PACKAGE.joinpath(*module.split(".")[1:])


def _is_package(module):
    return _path(module).is_dir()


def _exists(module):
    path = _path(module)
    return path.is_dir() or path.with_suffix(".py").is_file()


def upward_imports(source, module):
    """(module, imported) pairs where ``source``, the text of ``module``, imports a higher
    layer."""
    own = layer(module)
    return {(module, name) for name in imported_modules(source, module) if layer(name) > own}


SOURCES = sorted(PACKAGE.rglob("*.py"))
TESTS = Path(__file__).resolve().parent
TEST_SOURCES = sorted(TESTS.rglob("*.py"))


def test_every_module_has_a_layer():
    for path in SOURCES:
        layer(module_name(path))  # KeyError names the module


def test_no_module_imports_a_higher_layer():
    found = set()
    for path in SOURCES:
        found |= upward_imports(path.read_text(encoding="utf-8"), module_name(path))
    new = sorted(found - KNOWN_UPWARD)
    assert not new, "upward imports (module, imported): " + ", ".join(map(str, new))
    gone = sorted(KNOWN_UPWARD - found)
    assert not gone, f"no longer imported upwards, delete from KNOWN_UPWARD: {gone}"


@pytest.mark.parametrize(
    "module, source",
    [
        ("hemg_drake.teleop.browser", "from hemg_drake.pipeline import demonstrate"),
        ("hemg_drake.teleop.browser", "def f():\n    from hemg_drake import run_folder"),
        ("hemg_drake.evaluation", "import hemg_drake.viz.figures"),
        ("hemg_drake.emg.config", "from hemg_drake.emg.gain import A_EMG"),
        ("hemg_drake.control.pd", "from ..diagrams.station import SlaveStation"),
        ("hemg_drake.viz.ink", "from hemg_drake.sweep import run_sweep"),
    ],
)
def test_an_added_upward_import_is_caught(module, source):
    assert upward_imports(source, module) != set()


@pytest.mark.parametrize(
    "module, source",
    [
        ("hemg_drake.viz.ink", "from hemg_drake.analysis.contact import in_contact"),
        ("hemg_drake.pipeline", "from hemg_drake.teleop.browser import BrowserMaster"),
        ("hemg_drake.emg.config", "from hemg_drake.config_fields import checked"),
        ("hemg_drake.diagrams.station", "from hemg_drake.control.config import PdConfig"),
    ],
)
def test_a_downward_import_passes(module, source):
    assert upward_imports(source, module) == set()


def test_the_teleop_package_imports_neither_diagrams_nor_applications():
    for path in sorted((PACKAGE / "teleop").rglob("*.py")):
        names = imported_modules(path.read_text(encoding="utf-8"), module_name(path))
        assert not [n for n in names if layer(n) >= LAYERS.index("station")], path.name


def test_no_module_exceeds_the_line_limit():
    lines = {
        path.relative_to(PACKAGE).as_posix(): len(path.read_text(encoding="utf-8").splitlines())
        for path in SOURCES
    }
    # The tests' modules too, named from the repository (tests/...).
    for path in TEST_SOURCES:
        name = path.relative_to(TESTS.parent).as_posix()
        lines[name] = len(path.read_text(encoding="utf-8").splitlines())
    long = {name: n for name, n in lines.items() if n > KNOWN_LONG.get(name, MAX_LINES)}
    assert not long, f"modules over {MAX_LINES} lines (or longer than on main): {long}"
    fixed = [name for name in KNOWN_LONG if lines.get(name, 0) <= MAX_LINES]
    assert not fixed, f"now within {MAX_LINES} lines, delete from KNOWN_LONG: {fixed}"


MODEL_MODULES = ("hsmm", "hsmm_init", "hsmm_em", "hsmm_inference", "hsmm_io", "model_selection",
                 "sequences")  # fmt: skip


@pytest.mark.parametrize("name", MODEL_MODULES)
def test_the_model_does_not_import_the_reproduction(name):
    names, _ = _imports(PACKAGE / "learning" / f"{name}.py")
    assert not {n for n in names if n.startswith("hemg_drake.learning.") and "policy" in n}
    assert "hemg_drake.learning.reproduce" not in names


def _calls(tree):
    return {
        node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
    }


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
