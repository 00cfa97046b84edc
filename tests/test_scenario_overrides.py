"""Scenario overrides (--set): the key each sets, the file's other keys kept, later ones
winning, the checks after the last layer, and one-line errors naming the override at fault."""

import pytest

from hemg_drake.scenario import Scenario, load_scenario, parse_scenario, shipped_scenario


# --- overrides ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "override, key, value",
    [
        ("emg.k_max=150", "emg.k_max", 150.0),
        ("scene.position=[0.65,-0.80,0.12]", "scene.position", [0.65, -0.80, 0.12]),
        ("scene.yaw_deg=-20", "scene.yaw_deg", -20.0),
        ("scene.cotter_pin.hold_force=40", "scene.cotter_pin.hold_force", 40.0),
        ("scene.drawing.pen_stiffness=5000", "scene.drawing.pen_stiffness", 5000.0),
        ("learning.num_states=6", "learning.num_states", 6),
        ("learning.init=kmeans", "learning.init", "kmeans"),
        ("learning.reg_covar=0.3", "learning.reg_covar", 0.3),
        ("reproduction.weighting=forward", "reproduction.weighting", "forward"),
        ("reproduction.start_offsets=[[0, 0.01, 0]]", "reproduction.start_offsets", [[0, 0.01, 0]]),
        ("reproduction.tracking_gains=[20, 5]", "reproduction.tracking_gains", [20.0, 5.0]),
        ("mapping.delay_steps=25", "mapping.delay_steps", 25),
        ("mapping.rpy_deg=[90, 0, 0]", "mapping.rpy_deg", [90.0, 0.0, 0.0]),
        ("plant.time_step=0.0005", "plant.time_step", 0.0005),
        ("simulator.target_realtime_rate=1.0", "simulator.target_realtime_rate", 1.0),
        ("operator.path_std=[0, 0, 0.001]", "operator.path_std", [0.0, 0.0, 0.001]),
        ("num_demonstrations=2", "num_demonstrations", 2),
    ],
)
def test_override_sets_the_key(override, key, value):
    scenario = load_scenario(shipped_scenario("cotter_pin"), overrides=[override])
    node = scenario
    for name in key.split("."):
        node = getattr(node, name)
    assert node == value
    # Scenario.replaced gives the same scenario as the file read with the override.
    replaced = load_scenario(shipped_scenario("cotter_pin")).replaced([override])
    assert replaced.to_yaml() == scenario.to_yaml()


def test_override_keeps_the_files_other_keys_and_later_overrides_win():
    file = load_scenario(shipped_scenario("cotter_pin"))
    scenario = load_scenario(
        shipped_scenario("cotter_pin"), overrides=["emg.k_max=150", "emg.k_max=170"]
    )
    assert scenario.emg.k_max == 170.0
    assert scenario.emg.k_min == file.emg.k_min == 10.0
    assert scenario.mapping.scene_offset == file.mapping.scene_offset == [0.0, 0.0, 0.05]
    assert scenario.seed == file.seed == 1
    # The copy is new, down to its sections' lists: the original is unchanged.
    assert file.replaced(["seed=7"]).seed == 7 and file.seed == 1
    for copy in (file.replaced(["seed=7"]), file.replaced([])):
        assert copy is not file
        copy.operator.path_std[0] = 1.0
        copy.plant.time_step = 5e-4
    assert file.operator.path_std[0] == 0.003 and file.plant.time_step == 1e-3


def test_values_are_checked_once_after_the_last_layer():
    # The file's k_max is 200: k_min = 250 alone is refused, but overrides may pass through
    # it on their way to a valid scenario (each layer is loaded, the result checked once).
    with pytest.raises(ValueError, match=r"^--set emg\.k_min=250: keys 'emg\.k_min' < 'emg\.k_max'"):
        load_scenario(shipped_scenario("cotter_pin"), overrides=["emg.k_min=250"])
    scenario = load_scenario(shipped_scenario("cotter_pin"),
                             overrides=["emg.k_min=250", "emg.k_max=300"])  # fmt: skip
    assert (scenario.emg.k_min, scenario.emg.k_max) == (250.0, 300.0)
    # A rule between two keys blames the last override that set either.
    with pytest.raises(ValueError, match=r"^--set reproduction\.tracker=lqr: "):
        load_scenario(shipped_scenario("cotter_pin"),
                      overrides=["reproduction.weighting=spatial", "reproduction.tracker=lqr"])  # fmt: skip


def test_override_of_a_section_given_in_yaml():
    scenario = parse_scenario("", overrides=["emg={k_max: 120, window: 30}"])
    assert (scenario.emg.k_max, scenario.emg.window) == (120.0, 30)
    assert scenario.emg.k_min == Scenario().emg.k_min


@pytest.mark.parametrize(
    "override, words",
    [
        ("emg.kmax=150", ["emg.kmax"]),
        ("scenes.position=[0, 0, 0]", ["scenes"]),
        ("scene.cotter_pin.grip=3", ["scene.cotter_pin.grip"]),
        ("scene.position=[0.65,", ["malformed YAML"]),
        ("emg.k_max", ["key=value"]),
        ("=3", ["key=value"]),
        ("emg..k_max=3", ["key=value"]),
        ("emg=3", ["emg", "mapping"]),
        ("duration.seconds=3", ["duration", "holds a value, not a section"]),
        ("emg.k_max=high", ["emg.k_max", "number"]),
        ("learning.num_states=2.5", ["learning.num_states", "integer"]),
        ("emg.k_max=-5", ["emg.k_max", "negative"]),
        ("mapping.scale=0", ["mapping.scale", "positive"]),
        ("master.mass=.nan", ["master.mass", "finite"]),
        ("operator.rest_activation=1.5", ["operator.rest_activation", "[0, 1]"]),
        ("learning.init=random", ["learning.init", "random"]),
        ("reproduction.weighting=backward", ["reproduction.weighting", "backward"]),
        ("scene.position=[0.65, -0.80]", ["scene.position", "3 numbers"]),
        ("mapping.rpy_deg=[90, 0]", ["mapping.rpy_deg", "3 numbers"]),
        ("reproduction.tracking_gains=[50]", ["reproduction.tracking_gains", "2 numbers"]),
        ("reproduction.start_offsets=[[0, 0]]", ["reproduction.start_offsets"]),
        ("scene.cotter_pin.hold_force=-1", ["scene.cotter_pin"]),
    ],
)
def test_bad_override_is_one_line_naming_the_override_and_key(override, words):
    with pytest.raises(ValueError) as error:
        load_scenario(shipped_scenario("cotter_pin"), overrides=[override])
    message = str(error.value)
    assert "\n" not in message
    assert f"--set {override}" in message
    for word in words:
        assert word in message


def test_bad_override_through_replaced_names_its_source():
    with pytest.raises(ValueError, match=r"^--set emg\.kmax=1: .*emg\.kmax"):
        Scenario().replaced(["emg.kmax=1"])


def test_a_failed_check_names_the_override_at_fault():
    from hemg_drake.scenario import load_scenario, shipped_scenario

    with pytest.raises(ValueError) as error:
        load_scenario(shipped_scenario("cotter_pin"), overrides=["seed=3", "emg.k_max=-5"])
    assert str(error.value).startswith("--set emg.k_max=-5: key 'emg.k_max'")
    with pytest.raises(ValueError, match="needs a value after '='"):
        load_scenario(shipped_scenario("cotter_pin"), overrides=["emg.k_max="])
    with pytest.raises(ValueError, match="the scenario file is empty"):
        path = shipped_scenario("cotter_pin").parent / "nonexistent.yaml"  # noqa: F841
        import tempfile
        from pathlib import Path

        with tempfile.TemporaryDirectory() as folder:
            empty = Path(folder) / "empty.yaml"
            empty.write_text("{}\n")
            load_scenario(empty)


@pytest.mark.parametrize(
    "override, message",
    [
        ("pd.stiffness_scale=[1, 2]", "key 'pd.stiffness_scale' must hold 7 numbers"),
        ("pd.stiffness_scale=[20, 20, 10, 10, 2, 2, 0]", "key 'pd.stiffness_scale' must be positive"),
        ("pd.damping_ratio=-1", "key 'pd.damping_ratio' must be positive"),
        ("pd.gain=.nan", "key 'pd.gain' must be finite"),
        ("clik.limit_margin=-0.1", "key 'clik.limit_margin' must not be negative"),
    ],
)
def test_the_controllers_new_keys_refuse_bad_values_naming_the_override(override, message):
    # The pd section and clik.limit_margin came with the configs beside their systems.
    with pytest.raises(ValueError) as error:
        load_scenario(shipped_scenario("cotter_pin"), overrides=[override])
    text = str(error.value)
    assert text.startswith(f"--set {override}: ") and message in text and "\n" not in text
