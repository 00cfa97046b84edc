"""Scenarios: the shipped files, configs that own their defaults and checks, --set
overrides, the placed scene, and errors that name the file (or the override) and the key."""

import ast
import dataclasses as dc
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed

import hemg_drake
from hemg_drake.config_fields import check_config
from hemg_drake.control.config import ClikConfig, PdConfig
from hemg_drake.emg.config import EmgConfig
from hemg_drake.learning.config import LearningConfig, ReproductionConfig
from hemg_drake.scenario import Scenario, load_scenario, parse_scenario, shipped_scenario
from hemg_drake.tasks.config import (
    CotterPinParams,
    DrawingParams,
    PlacementsConfig,
    PlanConfig,
    SceneConfig,
)
from hemg_drake.teleop.config import FeedbackConfig, MappingConfig, MasterConfig, OperatorConfig

PACKAGE = Path(hemg_drake.__file__).parent


def Rz(yaw_deg):
    """Rotation about +z by ``yaw_deg`` degrees, written out."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# --- the shipped scenarios ---------------------------------------------------------------


@pytest.mark.parametrize(
    "name, demos, states, positions, init",
    [("cotter_pin", 4, 4, "tool", "time"), ("drawing", 3, 18, "reference", "polyline")],
)
def test_shipped_scenarios_load_from_the_package(name, demos, states, positions, init):
    path = shipped_scenario(name)
    # Shipped inside the package (found with importlib.resources), not beside the checkout.
    assert path.parent == Path(hemg_drake.__file__).parent / "scenarios"
    scenario = load_scenario(path)
    assert scenario.task == name
    assert scenario.num_demonstrations == demos
    assert scenario.learning.num_states == states
    assert (scenario.learning.positions, scenario.learning.init) == (positions, init)
    assert scenario.log_period == 0.01 and scenario.plant.time_step == 1e-3
    assert scenario.emg.window == 20 and scenario.emg.A_emg == -0.6981
    assert scenario.emg.k_max == 200.0 and scenario.mapping.scale == 2.0
    assert len(scenario.scene.position) == 3
    assert scenario.reproduction.weighting == "temporal"
    assert scenario.reproduction.restoring_gain == 2.0
    assert len(scenario.reproduction.start_offsets) == 1
    seeds = scenario.seeds()
    assert seeds == list(range(scenario.seed, scenario.seed + demos))


def test_unknown_shipped_scenario():
    with pytest.raises(FileNotFoundError, match="no shipped scenario named 'welding'"):
        shipped_scenario("welding")


# --- configs beside their systems own the defaults and the checks ------------------------

# Each section of a scenario and the config class of its package that it must be.
SECTIONS = {
    "scene": SceneConfig,
    "mapping": MappingConfig,
    "master": MasterConfig,
    "operator": OperatorConfig,
    "emg": EmgConfig,
    "clik": ClikConfig,
    "pd": PdConfig,
    "feedback": FeedbackConfig,
    "learning": LearningConfig,
    "reproduction": ReproductionConfig,
}
CONFIGS = sorted(
    {*SECTIONS.values(), CotterPinParams, DrawingParams, PlacementsConfig, PlanConfig},
    key=lambda config: config.__name__,
)


@pytest.mark.parametrize("section", sorted(SECTIONS))
def test_every_section_is_a_config_class_from_its_package(section):
    config = getattr(Scenario(), section)
    assert type(config) is SECTIONS[section]
    # Beside its systems: hemg_drake.<package>.config.
    assert type(config).__module__.split(".")[-1] == "config"


@pytest.mark.parametrize("path", sorted(PACKAGE.glob("*/config.py")), ids=lambda p: p.parent.name)
def test_config_modules_import_no_system(path):
    # The standard library, numpy, the field helper; tasks also the argument checks and the
    # TaskPlan a written-out plan must make (both numpy only).
    allowed = {"dataclasses", "typing", "numpy", "hemg_drake.config_fields",
               "hemg_drake._validate", "hemg_drake.tasks.plan"}  # fmt: skip
    tree = ast.parse(path.read_text(encoding="utf-8"))
    imported = {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import)
                for alias in node.names}  # fmt: skip
    imported |= {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert imported <= allowed, imported - allowed


@pytest.mark.parametrize("config", CONFIGS, ids=lambda config: config.__name__)
def test_config_defaults_round_trip_through_yaml(config):
    text = yaml_dump_typed(config())
    assert dc.asdict(yaml_load_typed(schema=config, data=text)) == dc.asdict(config())
    # And every default is a value its own checks accept (but PlanConfig's: a scenario
    # without a plan has none, and an empty plan is no plan).
    if config is not PlanConfig:
        check_config(config(), "section")


@pytest.mark.parametrize(
    "config, key, message",
    [
        (EmgConfig(k_min=300.0, k_max=200.0), "k_min", r"keys 'x\.k_min' < 'x\.k_max'"),
        (EmgConfig(calibration_duration=0.05), "calibration_duration",
         r"key 'x\.calibration_duration' gives 10 samples, fewer than the window 'x\.window'"),
        (ReproductionConfig(tracker="lqr", weighting="spatial"), "weighting",
         r"key 'x\.weighting' = 'spatial' does not go with 'x\.tracker' = 'lqr'"),
        (ReproductionConfig(start_offsets=[[0.0, 0.0]]), "start_offsets",
         r"key 'x\.start_offsets' must hold \[dx, dy, dz\]"),
        (PlacementsConfig(position_range=[[0.7, 0, 0], [0.6, 0, 0]]), "position_range",
         r"key 'x\.position_range' must be .* each min <= max"),
        (PlacementsConfig(yaw_range_deg=[10.0, -10.0]), "yaw_range_deg",
         r"key 'x\.yaw_range_deg' must be \[smallest, largest\]"),
        (PlanConfig(times=[0.0, 1.0], points=[[0, 0, 0]], kinds=["free"]), "points",
         r"key 'x': TaskPlan field 'points'"),
        (CotterPinParams(), "hold_force", r"key 'x\.hold_force' must be finite and > 0"),
        (DrawingParams(), "pen_radius", r"key 'x\.pen_radius' must be finite and > 0"),
    ],
)  # fmt: skip
def test_each_config_check_names_its_key(config, key, message):
    if isinstance(config, (CotterPinParams, DrawingParams)):
        setattr(config, key, 0.0)  # their fields are checked on construction
    with pytest.raises(ValueError, match=message):
        config.check("x")
    # The scenario calls it with the section's key path, after the fields' own checks.
    with pytest.raises(ValueError, match=message.replace("'x", "'a\\.b")):
        check_config(config, "a.b")


def test_field_metadata_checks_name_the_key_under_the_prefix():
    with pytest.raises(ValueError, match=r"^key 'mapping\.scale' must be positive, got 0"):
        check_config(MappingConfig(scale=0.0), "mapping")
    with pytest.raises(ValueError, match=r"^key 'scene\.position' must hold 0 or 3 numbers"):
        check_config(SceneConfig(position=[1.0, 2.0]), "scene")
    with pytest.raises(ValueError, match=r"^key 'operator\.path_std' must be finite"):
        check_config(OperatorConfig(path_std=[0.0, math.nan, 0.0]), "operator")


def test_loading_a_scenario_imports_no_system():
    """Loading the shipped scenarios and building their plans and poses imports neither
    numba, scipy nor any module of the package that defines a system."""
    code = (
        "import sys\n"
        "from hemg_drake.scenario import load_scenario, shipped_scenario\n"
        "for name in ('cotter_pin', 'drawing'):\n"
        "    scenario = load_scenario(shipped_scenario(name))\n"
        "    scenario.task_plan(), scenario.X_WT(), scenario.R_WM()\n"
        "print(' '.join(sorted(sys.modules)))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, cwd=PACKAGE.parent)  # fmt: skip
    modules = result.stdout.split()
    assert "hemg_drake.scenario" in modules
    assert not [m for m in modules if m.split(".")[0] in ("numba", "scipy")]
    for known in ("hemg_drake.tasks.cotter_pin", "hemg_drake.tasks.drawing",
                  "hemg_drake.teleop.mapping", "hemg_drake.robots.baxter"):  # fmt: skip
        assert known not in modules
    # No module of the package that was loaded defines a system or builds a diagram.
    ours = [m for m in modules if m.startswith("hemg_drake.")]
    for module in ours:
        path = PACKAGE.parent.joinpath(*module.split("."))
        source = (path / "__init__.py" if path.is_dir() else path.with_suffix(".py")).read_text()
        assert "LeafSystem" not in source and "DiagramBuilder" not in source, module


def test_plant_defaults_to_live_output_ports_and_yaml_can_sample_them():
    plant = parse_scenario("").plant
    assert plant.time_step == 1e-3 and not plant.use_sampled_output_ports
    assert plant.contact_model == "point"
    sampled = parse_scenario("plant: {use_sampled_output_ports: true}\n").plant
    assert sampled.use_sampled_output_ports and sampled.time_step == 1e-3


def test_partial_sections_keep_the_other_defaults():
    scenario = parse_scenario("emg: {k_max: 300}\nmapping: {scale: 3}\n")
    assert scenario.emg.k_max == 300.0 and scenario.emg.k_min == Scenario().emg.k_min
    assert scenario.mapping.scale == 3.0
    assert scenario.mapping.scene_offset == Scenario().mapping.scene_offset


# --- a moved and turned scene moves the plan and the workspace map -----------------------


@pytest.mark.parametrize("task", ["cotter_pin", "drawing"])
@pytest.mark.parametrize("yaw_deg", [0.0, 30.0, -90.0])
def test_moved_scene_moves_the_plan_and_the_map(task, yaw_deg):
    home = load_scenario(shipped_scenario(task))
    p_WT_home = np.array(home.scene.position)
    p_WT = np.array([0.60, -0.75, 0.15])
    moved = home.replaced([f"scene.position={p_WT.tolist()}", f"scene.yaw_deg={yaw_deg}"])
    R = Rz(yaw_deg)

    # Plan: every waypoint is the home waypoint, taken in the scene frame, turned and moved.
    plan_home, plan = home.task_plan(), moved.task_plan()
    np.testing.assert_array_equal(plan.times, plan_home.times)
    expected = p_WT + (np.asarray(plan_home.points) - p_WT_home) @ R.T
    np.testing.assert_allclose(plan.points, expected, rtol=0, atol=1e-12)

    # Map: the workspace centre is scene_offset in the scene frame; the master turns too.
    mapping = moved.workspace_mapping()
    offset_T = np.array(home.mapping.scene_offset)
    np.testing.assert_allclose(mapping.p_WMo, p_WT + R @ offset_T, rtol=0, atol=1e-12)
    R_WM_home = home.workspace_mapping().R_WM.matrix()
    np.testing.assert_allclose(mapping.R_WM.matrix(), R @ R_WM_home, rtol=0, atol=1e-12)
    # So a stylus point maps onto the same place relative to the scene as at home.
    p_MS = np.array([0.01, -0.02, 0.03])
    at_home = home.workspace_mapping().master_to_slave(p_MS) - p_WT_home
    np.testing.assert_allclose(
        mapping.master_to_slave(p_MS), p_WT + R @ at_home, rtol=0, atol=1e-12
    )


def test_home_scene_is_where_the_tasks_default_plans_stand():
    from hemg_drake.tasks.cotter_pin import DEFAULT_POSITION
    from hemg_drake.tasks.plans import default_cotter_pin_plan

    # An empty scene.position is the task's default position, unturned.
    np.testing.assert_allclose(Scenario().X_WT().translation(), DEFAULT_POSITION)
    np.testing.assert_allclose(Scenario().task_plan().points, default_cotter_pin_plan().points)


def test_default_rotation_is_the_mappings_behind_the_robot():
    from hemg_drake.teleop.mapping import R_WM_BEHIND_ROBOT

    np.testing.assert_allclose(Scenario().R_WM().matrix(), R_WM_BEHIND_ROBOT.matrix(), atol=1e-12)


def test_plan_override_is_in_the_scene_frame():
    text = (
        "scene: {position: [0.6, -0.8, 0.1], yaw_deg: 90}\n"
        "plan:\n  times: [0, 1, 3]\n  points: [[0, 0, 0], [0.1, 0, 0], [0.1, 0.1, 0.02]]\n"
        "  kinds: [free, forceful]\n  effort: [1.0, 1.5]\n"
    )
    plan = parse_scenario(text).task_plan()
    # Turned 90 deg about z: scene +x is world +y, scene +y is world -x.
    np.testing.assert_allclose(plan.position(0.0), [0.6, -0.8, 0.1], atol=1e-12)
    np.testing.assert_allclose(plan.position(1.0), [0.6, -0.7, 0.1], atol=1e-12)
    np.testing.assert_allclose(plan.position(3.0), [0.5, -0.7, 0.12], atol=1e-12)
    assert plan.kinds == ("free", "forceful") and plan.pen_down == (False, False)
    np.testing.assert_allclose(plan.effort, [1.0, 1.5])


# --- files that are not scenarios --------------------------------------------------------


@pytest.mark.parametrize("text", ["", "   \n", "# nothing but a comment\n"])
def test_empty_file_is_refused(tmp_path, text):
    path = tmp_path / "empty.yaml"
    path.write_text(text)
    with pytest.raises(ValueError) as error:
        load_scenario(path)
    message = str(error.value)
    assert message.startswith(str(path)) and "empty" in message and "\n" not in message


def test_folder_is_refused(tmp_path):
    with pytest.raises(ValueError) as error:
        load_scenario(tmp_path)
    message = str(error.value)
    assert message.startswith(str(tmp_path)) and "is a folder" in message
    assert "not found" not in message


def test_non_utf8_file_is_refused(tmp_path):
    path = tmp_path / "latin1.yaml"
    path.write_bytes("task: drawing\n# Müller\n".encode("latin-1"))
    with pytest.raises(ValueError) as error:
        load_scenario(path)
    message = str(error.value)
    assert message.startswith(str(path)) and "not UTF-8" in message and "\n" not in message


def test_missing_file():
    with pytest.raises(FileNotFoundError, match="nowhere.yaml"):
        load_scenario("nowhere.yaml")


@pytest.mark.parametrize(
    "text, words",
    [
        ("duration: [1", ["malformed YAML", "line 1"]),
        ("- 3\n", ["top level", "mapping"]),
        ("emg: {windw: 3}", ["emg.windw"]),
        ("plant: {step: 0.001}", ["plant.step"]),
        ("scene: {drawing: {ink: blue}}", ["scene.drawing.ink"]),
        ("emg: {k_max: high}", ["emg.k_max", "number"]),
        ("num_demonstrations: 2.5", ["num_demonstrations", "integer"]),
        ("operator: {path_std: [0.1, a, 0]}", ["operator.path_std[1]"]),
        ("task: welding", ["task", "welding", "cotter_pin"]),
        ("clik: {method: newton}", ["clik.method"]),
        ("feedback: {mode: voice}", ["feedback.mode"]),
        ("learning: {positions: master}", ["learning.positions"]),
        ("reproduction: {observe: both}", ["reproduction.observe"]),
        ("duration: -2", ["duration", "positive"]),
        ("seed: -1", ["seed", "negative"]),
        ("master: {mass: .nan}", ["master.mass", "finite"]),
        ("mapping: {scale: .inf}", ["mapping.scale", "finite"]),
        ("mapping: {scale: 0}", ["mapping.scale", "positive"]),
        ("learning: {num_states: 0}", ["learning.num_states", "positive"]),
        ("scene: {position: [1, 2]}", ["scene.position", "3 numbers"]),
        ("scene: {yaw_deg: .inf}", ["scene.yaw_deg", "finite"]),
        ("mapping: {scene_offset: [1, 2]}", ["mapping.scene_offset", "3 numbers"]),
        ("operator: {forceful_activation: 1.5}", ["operator.forceful_activation", "[0, 1]"]),
        ("emg: {k_min: 300, k_max: 200}", ["emg.k_min", "emg.k_max"]),
        ("emg: {calibration_duration: 0.05}", ["emg.calibration_duration", "emg.window"]),
        ("plant: {time_step: 0.01}", ["plant.time_step", "0.001"]),
        ("log_period: 0.0105", ["log_period", "multiple"]),
        ("scene: {cotter_pin: {detent_length: 0.06}}", ["scene.cotter_pin.detent_length", "0.05"]),
        ("plan: {times: [0, 1], points: [[0, 0, 0]], kinds: [free]}", ["plan", "points"]),
        ("plan: {times: [0, 1], points: [[0, 0, 0], [1, 1, 1]], kinds: [fly]}", ["plan", "kinds"]),
        # This round's keys: natural takes, shared control, stiffness policies.
        ("learning: {align: diagonal}", ["learning.align", "diagonal", "trim"]),
        ("operator: {style: robot}", ["operator.style", "robot", "human"]),
        ("operator: {human: {pause_probability: 2}}",
         ["operator.human.pause_probability", "[0, 1]"]),
        ("assist: {mode: bogus}", ["assist.mode", "bogus", "emg"]),
        ("reproduction: {stiffness: tensor}", ["reproduction.stiffness", "tensor", "spd"]),
        ("reproduction: {gain_source: guess}", ["reproduction.gain_source", "guess", "learnt"]),
        # The visual operator (issue 26's study) and the alignment's new value.
        ("learning: {align: warp}", ["learning.align", "warp", "dtw"]),
        ("operator: {visual: {patience: 0}}", ["operator.visual.patience", "positive"]),
        ("operator: {visual: {tolerance: -0.001}}", ["operator.visual.tolerance", "positive"]),
        ("operator: {visual: {tremor_frequency: [8.0]}}",
         ["operator.visual.tremor_frequency", "2"]),
    ],
)
def test_bad_scenarios_name_the_file_and_key(tmp_path, text, words):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ValueError) as error:
        load_scenario(path)
    message = str(error.value)
    assert message.startswith(str(path)) and "\n" not in message
    for word in words:
        assert word in message


# --- round trip --------------------------------------------------------------------------


def test_defaults_round_trip():
    assert parse_scenario(Scenario().to_yaml()).to_yaml() == Scenario().to_yaml()
    # And the defaults are what an (almost) empty file gives.
    assert parse_scenario("task: cotter_pin\n").to_yaml() == Scenario().to_yaml()


@pytest.mark.parametrize("name", ["cotter_pin", "drawing"])
def test_yaml_round_trip_keeps_every_key(name):
    scenario = load_scenario(
        shipped_scenario(name),
        overrides=[
            "seed=7",
            "scene.yaw_deg=15",
            "operator.path_std=[0.001, 0.002, 0]",
            "reproduction.start_offsets=[[0.01, 0, 0], [0, 0.02, 0]]",
            "plan={times: [0, 1], points: [[0, 0, 0], [0, 0, 0.1]], kinds: [free]}",
            "plant.use_sampled_output_ports=true",
        ],
    )
    again = parse_scenario(scenario.to_yaml())
    assert again.to_yaml() == scenario.to_yaml()
    assert dc.asdict(again.operator) == dc.asdict(scenario.operator)
    assert dc.asdict(again.reproduction) == dc.asdict(scenario.reproduction)
    assert dc.asdict(again.scene) == dc.asdict(scenario.scene)
    assert dc.asdict(again.plan) == dc.asdict(scenario.plan)
    assert again.plant.use_sampled_output_ports
    assert (again.seed, again.task) == (7, name)
    np.testing.assert_array_equal(again.task_plan().points, scenario.task_plan().points)


def test_every_scenario_key_is_documented():
    """docs/scenarios.md lists every key of the scenario (so the doc cannot fall behind)."""
    import dataclasses as dc
    from pathlib import Path

    from hemg_drake.scenario import Scenario

    text = (Path(__file__).resolve().parents[1] / "docs" / "scenarios.md").read_text()

    def keys(obj, prefix=""):
        for field in dc.fields(obj):
            value = getattr(obj, field.name)
            yield prefix + field.name
            if dc.is_dataclass(value) and not isinstance(value, type):
                yield from keys(value, f"{prefix}{field.name}.")

    missing = [key for key in keys(Scenario()) if f"`{key}`" not in text]
    assert not missing, f"docs/scenarios.md does not list {missing}"


def test_numbers_in_scientific_notation_are_numbers():
    """YAML 1.1 reads 2e-3 and 3.0e4 as text; a scenario reads them as the numbers they are."""
    from hemg_drake.scenario import load_scenario, parse_scenario, shipped_scenario

    scenario = load_scenario(
        shipped_scenario("cotter_pin"),
        overrides=["master.period=2e-3", "scene.cotter_pin.detent_stiffness=3.0e4"],
    )
    assert scenario.master.period == 0.002
    assert scenario.scene.cotter_pin.detent_stiffness == 30000.0
    parsed = parse_scenario("task: drawing\nmapping:\n  scene_offset: [1e-2, 0, -2E-2]\n")
    assert parsed.mapping.scene_offset == [0.01, 0.0, -0.02]
    with pytest.raises(ValueError, match="key 'duration' must be a number, got 'e3'"):
        parse_scenario("duration: e3\n")
