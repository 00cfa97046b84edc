"""Scenario loading: the shipped files, defaults, round trip, and errors that name the key."""

from pathlib import Path

import numpy as np
import pytest

from hemg_drake.scenario import Scenario, load_scenario, parse_scenario

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.mark.parametrize(
    "name, task, demos, states", [("cotter_pin", "cotter_pin", 4, 4), ("drawing", "drawing", 3, 18)]
)
def test_shipped_scenarios_match_the_paper(name, task, demos, states):
    scenario = load_scenario(SCENARIOS / f"{name}.yaml")
    assert scenario.task == task
    assert (scenario.num_demonstrations, scenario.num_states) == (demos, states)
    assert scenario.log_period == 0.01 and scenario.plant.time_step == 1e-3
    assert scenario.emg.window == 20 and scenario.emg.A_emg == -0.6981
    seeds = scenario.seeds()
    assert len(set(seeds)) == demos and seeds[0] == scenario.seed


def test_partial_sections_keep_the_other_defaults():
    scenario = parse_scenario("emg: {k_max: 300}\nmapping: {scale: 3}\n")
    assert scenario.emg.k_max == 300.0 and scenario.emg.k_min == Scenario().emg.k_min
    assert scenario.mapping.scale == 3.0
    assert scenario.mapping.offset == Scenario().mapping.offset


def test_plant_defaults_to_live_output_ports_and_yaml_can_sample_them():
    plant = parse_scenario("").plant
    assert plant.time_step == 1e-3 and not plant.use_sampled_output_ports
    sampled = parse_scenario("plant: {use_sampled_output_ports: true}\n").plant
    assert sampled.use_sampled_output_ports and sampled.time_step == 1e-3


def test_yaml_round_trip():
    scenario = parse_scenario("task: drawing\nseed: 7\noperator: {path_std: [0.001, 0.002, 0]}\n")
    again = parse_scenario(scenario.to_yaml())
    assert again.to_yaml() == scenario.to_yaml()
    assert again.operator.path_std == [0.001, 0.002, 0.0] and again.seed == 7


def test_plan_override_becomes_the_task_plan():
    scenario = parse_scenario(
        "plan:\n  times: [0, 1, 3]\n  points: [[0.6, -0.8, 0.1], [0.7, -0.8, 0.1], [0.7, -0.7, 0.1]]\n"
        "  kinds: [free, forceful]\n  effort: [1.0, 1.5]\n"
    )
    plan = scenario.task_plan()
    np.testing.assert_allclose(plan.position(3.0), [0.7, -0.7, 0.1])
    assert plan.kinds == ("free", "forceful") and plan.pen_down == (False, False)
    np.testing.assert_allclose(plan.effort, [1.0, 1.5])


def test_default_rotation_is_the_mappings_behind_the_robot():
    from hemg_drake.teleop.mapping import R_WM_BEHIND_ROBOT

    np.testing.assert_allclose(Scenario().R_WM().matrix(), R_WM_BEHIND_ROBOT.matrix(), atol=1e-12)


@pytest.mark.parametrize(
    "text, words",
    [
        ("duration: [1", ["malformed YAML", "line 1"]),
        ("- 3\n", ["top level", "mapping"]),
        ("emg: {windw: 3}", ["emg.windw"]),
        ("plant: {step: 0.001}", ["plant.step"]),
        ("emg: {k_max: high}", ["emg.k_max", "number"]),
        ("num_demonstrations: 2.5", ["num_demonstrations", "integer"]),
        ("operator: {path_std: [0.1, a, 0]}", ["operator.path_std[1]"]),
        ("task: welding", ["task", "welding", "cotter_pin"]),
        ("clik: {method: newton}", ["clik.method"]),
        ("feedback: {mode: voice}", ["feedback.mode"]),
        ("duration: -2", ["duration", "negative"]),
        ("master: {mass: .nan}", ["master.mass", "finite"]),
        ("mapping: {scale: .inf}", ["mapping.scale", "finite"]),
        ("mapping: {scale: 0}", ["mapping.scale", "positive"]),
        ("mapping: {offset: [1, 2]}", ["mapping.offset", "3 numbers"]),
        ("operator: {forceful_activation: 1.5}", ["operator.forceful_activation", "[0, 1]"]),
        ("emg: {k_min: 300, k_max: 200}", ["emg.k_min", "emg.k_max"]),
        ("plant: {time_step: 0.01}", ["plant.time_step", "0.001"]),
        ("log_period: 0.0105", ["log_period", "multiple"]),
        ("plan: {times: [0, 1], points: [[0, 0, 0]], kinds: [free]}", ["plan", "points"]),
        ("plan: {times: [0, 1], points: [[0, 0, 0], [1, 1, 1]], kinds: [fly]}", ["plan", "kinds"]),
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


def test_missing_file():
    with pytest.raises(FileNotFoundError, match="nowhere.yaml"):
        load_scenario("nowhere.yaml")


def test_empty_file_is_all_defaults(tmp_path):
    path = tmp_path / "empty.yaml"
    path.write_text("# nothing\n")
    assert load_scenario(path).to_yaml() == Scenario().to_yaml()
