"""Every value checked at load, before anything runs (issue 25): Drake's strings against what
Drake itself accepts, sizes against their derived bounds, seeds within Drake's 32 bits, keys
given twice, and overrides of keys a command does not read. Each is one line naming the file
or the override, the key and what is allowed."""

import pytest
from pydrake.common import RandomGenerator
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator, SimulatorConfig
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from hemg_drake.scenario import (
    FREE_STRINGS, Scenario, check_overrides_read, drake_choices, load_scenario, parse_scenario,
    shipped_scenario,
)  # fmt: skip
from hemg_drake.sweep.spec import parse_sweep
from hemg_drake.yaml_schema import schema_fields


def load_pin(*overrides):
    return load_scenario(shipped_scenario("cotter_pin"), overrides=list(overrides))


def refused(override, *, task="cotter_pin"):
    """The one-line message of loading the shipped scenario with ``override``."""
    with pytest.raises(ValueError) as error:
        load_scenario(shipped_scenario(task), overrides=[override])
    message = str(error.value)
    assert "\n" not in message and message.startswith(f"--set {override}: "), message
    return message


# --- Drake's strings -----------------------------------------------------------------------


def drake_accepts(path, value):
    """Drake's own verdict on a string of its config structs: apply it (the reference)."""
    section, name = path.split(".")
    try:
        if section == "plant":
            AddMultibodyPlant(MultibodyPlantConfig(**{name: value}), DiagramBuilder())
        else:
            simulator = Simulator(ConstantVectorSource([1.0]))
            ApplySimulatorConfig(SimulatorConfig(**{name: value}), simulator)
    except RuntimeError as error:
        # CENIC asks for a diagram with a plant: the name is known, the system is not its kind.
        return "Unknown" not in str(error)
    return True


def test_every_string_of_drakes_structs_is_checked_or_free():
    # A string field Drake adds to one of the scenario's structs must be listed here.
    strings = set()
    for section, schema in schema_fields(Scenario).items():
        if hasattr(schema, "__fields__"):
            strings |= {f"{section}.{f.name}" for f in schema.__fields__ if f.type is str}
    assert strings == set(drake_choices()) | set(FREE_STRINGS)
    assert set(drake_choices()) == {
        "simulator.integration_scheme", "plant.contact_model",
        "plant.discrete_contact_approximation", "plant.contact_surface_representation",
    }  # fmt: skip


@pytest.mark.parametrize("path", sorted(drake_choices()))
def test_the_allowed_strings_are_those_drake_accepts(path):
    choices = drake_choices()[path]
    assert len(choices) >= 2
    for value in choices:
        assert drake_accepts(path, value), value
        load_pin(f"{path}={value}")  # accepted at load too
    for typo in ("hydroelastc", "Point", "rk4", "none"):
        assert typo not in choices and not drake_accepts(path, typo)


@pytest.mark.parametrize(
    "override, allowed",
    [
        ("plant.contact_model=hydroelastc", "'point', 'hydroelastic', 'hydroelastic_with_fallback'"),
        ("plant.discrete_contact_approximation=foo", "'tamsi', 'sap', 'similar', 'lagged'"),
        ("plant.contact_surface_representation=quads", "'triangle', 'polygon'"),
        ("simulator.integration_scheme=rk9", "'runge_kutta3'"),
    ],
)  # fmt: skip
def test_a_string_drake_refuses_is_one_line_naming_key_value_and_choices(override, allowed):
    key, value = override.split("=")
    message = refused(override)
    assert f"key '{key}' = '{value}' is not one of (" in message and allowed in message


def test_the_drawing_needs_point_contact_at_load():
    message = refused("plant.contact_model=hydroelastic", task="drawing")
    assert "'task' = 'drawing'" in message and "point contact" in message
    load_pin("plant.contact_model=hydroelastic")  # the pin takes any


# --- sizes -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "key, bound, why",
    [
        ("mapping.delay_steps", 10_000, "10 s of the master's 1 ms samples"),
        ("feedback.delay_steps", 10_000, "10 s of the master's 1 ms samples"),
        ("reproduction.horizon", 1000, "10 s of 0.01 s steps"),
        ("learning.num_states", 100, ""),
        ("learning.n_iter", 1000, ""),
        ("num_demonstrations", 100, ""),
        ("emg.calibration_duration", 60, ""),
        ("reproduction.settle_time", 60, ""),
    ],
)
def test_sizes_are_bounded_and_the_bound_itself_loads(key, bound, why):
    scenario = load_pin(f"{key}={bound}")
    node = scenario
    for name in key.split("."):
        node = getattr(node, name)
    assert node == bound
    for value in (bound + 1, 1_000_000_000):
        message = refused(f"{key}={value}")
        assert f"key '{key}' must be at most {bound}" in message and why in message


def test_a_size_in_scientific_notation_is_not_an_integer():
    # YAML 1.1 reads 1e9 as text; an integer key says so instead of allocating.
    assert "key 'mapping.delay_steps' must be an integer, got '1e9'" in refused(
        "mapping.delay_steps=1e9"
    )


def test_seeds_stay_within_drakes_32_bits():
    # Drake's generator wraps a seed to 32 bits: 2**32 draws what 0 draws (the reason).
    assert RandomGenerator(2**32)() == RandomGenerator(0)()
    last = 2**32 - 1
    assert load_pin(f"seed={last}", "num_demonstrations=1").seeds() == [last]
    message = refused(f"seed={last - 2}")  # the shipped 4 demonstrations: up to last + 1
    assert f"seeds up to {last + 1}" in message and str(last) in message
    assert "num_demonstrations" in message


def test_a_zero_activation_shape_is_refused_at_load():
    assert "key 'emg.A_emg' must not be 0" in refused("emg.A_emg=0")


def test_a_cross_field_rule_broken_by_an_override_blames_the_override():
    # The shipped k_max is 200: k_min 300 breaks k_min < k_max, and the --set is at fault.
    message = refused("emg.k_min=300")
    assert "keys 'emg.k_min' < 'emg.k_max'" in message
    dataset_scenario = parse_scenario(load_pin().to_yaml(), source="run/dataset.npz metadata")
    with pytest.raises(ValueError, match=r"^--set emg\.k_min=300: keys 'emg\.k_min'"):
        dataset_scenario.replaced(["emg.k_min=300"])


# --- keys given twice ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "text, key, lines",
    [
        ("task: cotter_pin\nseed: 1\nseed: 2\n", "seed", "at lines 2 and 3"),
        ("task: drawing\nemg:\n  k_max: 100\n  window: 20\n  k_max: 300\n", "emg.k_max",
         "at lines 3 and 5"),
        ("task: drawing\nemg: {k_max: 100}\nemg: {window: 30}\n", "emg", "at lines 2 and 3"),
    ],
)  # fmt: skip
def test_a_key_given_twice_in_a_scenario_file_is_refused(tmp_path, text, key, lines):
    path = tmp_path / "twice.yaml"
    path.write_text(text)
    with pytest.raises(ValueError) as error:
        load_scenario(path)
    assert str(error.value) == f"{path}: key '{key}' is given twice, {lines}: give it once"


def test_a_key_given_twice_in_an_override_value_or_a_sweep_file_is_refused():
    message = refused("emg={k_max: 150, k_max: 170}")
    assert "key 'k_max' is given twice, on line 1" in message
    sweep = "scenario: cotter_pin\nseeds: [1]\nseeds: [2]\n"
    with pytest.raises(ValueError, match=r"^s\.yaml: key 'seeds' is given twice, at lines 2 and 3"):
        parse_sweep(sweep, source="s.yaml")
    # Later --set overrides still win over earlier ones: each is a layer of its own.
    assert load_pin("emg.k_max=150", "emg.k_max=170").emg.k_max == 170.0


# --- overrides a command does not read ----------------------------------------------------


@pytest.mark.parametrize(
    "override, message",
    [
        ("emg.k_max=150", "--set emg.k_max=150: learn does not use emg.*: it reads learning.* and seed"),
        ("emg={k_max: 150}", "learn does not use emg.*"),
        ("duration=2", "learn does not use duration: it reads"),
        ("task=drawing", "--set task=drawing: the task of a run folder is fixed"),
    ],
)  # fmt: skip
def test_an_override_learn_does_not_read_is_refused(override, message):
    with pytest.raises(ValueError) as error:
        check_overrides_read([override], ("learning", "seed"), reader="learn")
    assert message in str(error.value) and "\n" not in str(error.value)


def test_overrides_a_reader_reads_pass():
    reads = ("reproduction", "scene.position", "emg.k_max")
    check_overrides_read(
        ["reproduction.tracker=lqr", "reproduction={weighting: forward}", "scene.position=[]",
         "emg.k_max=300", "emg.kmax"],  # a malformed one is left for the load to name
        reads, reader="reproduce",
    )  # fmt: skip
    with pytest.raises(ValueError, match="reproduce does not use emg.window: it reads "
                                         r"reproduction\.\*, scene\.position and emg\.k_max"):
        check_overrides_read(["emg.window=3"], reads, reader="reproduce")
