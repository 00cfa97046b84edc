"""Issue 25's probes of bad values through the command line: each is one line on stderr, exit
status 2, and nothing written or changed (the output folder is not made; a run folder keeps
its bytes). Nothing here simulates: a probe that got past the checks would fail the test."""

import sys

import numpy as np
import pytest

import hemg_drake.pipeline as pipeline
from hemg_drake.learning.demos import Demonstration, save_dataset
from hemg_drake.run_folder import RunFolder
from hemg_drake.scenario import load_scenario, shipped_scenario


@pytest.fixture
def run_folder(tmp_path):
    """A run folder with a finished demonstrate stage of two straight-line demonstrations of
    the shipped cotter-pin scenario (k_max 200); no simulation."""
    run = tmp_path / "run"
    scenario = load_scenario(shipped_scenario("cotter_pin"))
    t = np.arange(0.0, 1.0 + 1e-9, 0.01)
    demos = []
    for c in range(2):
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


def snapshot(folder):
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def no_jobs(monkeypatch):
    """Every pipeline job fails the test if it is reached: the checks must come first."""
    import hemg_drake.demo as demo

    for module, name in ((pipeline, "demonstrate"), (pipeline, "learn"), (pipeline, "reproduce"),
                         (demo, "run_demo")):  # fmt: skip
        def reached(*args, _name=name, **kwargs):
            pytest.fail(f"{_name} was reached")

        monkeypatch.setattr(module, name, reached)


def one_line(code, out, err, command):
    assert code == 2 and "Traceback" not in err, err
    assert err.count("\n") == 1 and err.startswith(f"hemg-drake {command}: error: "), err
    return err


# Scenario values refused at load: (override, words of the message).
DEMONSTRATE_PROBES = [
    ("plant.contact_model=hydroelastc",
     "--set plant.contact_model=hydroelastc: key 'plant.contact_model' = 'hydroelastc' is not "
     "one of ('point', 'hydroelastic', 'hydroelastic_with_fallback')"),
    ("simulator.integration_scheme=rk9", "key 'simulator.integration_scheme' = 'rk9' is not one of"),
    ("plant.discrete_contact_approximation=foo",
     "key 'plant.discrete_contact_approximation' = 'foo' is not one of ('tamsi', 'sap', "
     "'similar', 'lagged')"),
    ("mapping.delay_steps=1000000000",
     "key 'mapping.delay_steps' must be at most 10000 (10 s of the master's 1 ms samples)"),
    ("feedback.delay_steps=1000000000", "key 'feedback.delay_steps' must be at most 10000"),
    ("num_demonstrations=1000000000", "key 'num_demonstrations' must be at most 100"),
    ("emg.calibration_duration=1e9", "key 'emg.calibration_duration' must be at most 60"),
    ("emg.k_min=300", "--set emg.k_min=300: keys 'emg.k_min' < 'emg.k_max' required"),
    ("seed=4294967295", "Drake's random generator takes seeds up to 4294967295"),
    ("emg.A_emg=0", "key 'emg.A_emg' must not be 0"),
]  # fmt: skip


@pytest.mark.parametrize("override, words", DEMONSTRATE_PROBES)
def test_demonstrate_refuses_a_bad_value_before_making_its_folder(
    tmp_path, run_cli, no_jobs, override, words
):
    out = tmp_path / "out"
    code, stdout, err = run_cli(["demonstrate", "cotter_pin", "--out", str(out), "--set", override])
    assert words in one_line(code, stdout, err, "demonstrate") and stdout == ""
    assert not out.exists()


def test_a_key_given_twice_in_the_scenario_file_is_one_line(tmp_path, run_cli, no_jobs):
    path = tmp_path / "mine.yaml"
    path.write_text("task: cotter_pin\nemg:\n  k_max: 150\n  k_max: 250\n")
    out = tmp_path / "out"
    code, stdout, err = run_cli(["demonstrate", str(path), "--out", str(out)])
    assert one_line(code, stdout, err, "demonstrate") == (
        f"hemg-drake demonstrate: error: {path}: key 'emg.k_max' is given twice, at lines 3 "
        "and 4: give it once\n"
    )
    assert not out.exists()


@pytest.mark.parametrize(
    "argv, words",
    [
        (["learn", "{run}", "--set", "emg.k_max=150"],
         "--set emg.k_max=150: learn does not use emg.*: it reads learning.* and seed"),
        (["learn", "{run}", "--set", "task=drawing"],
         "--set task=drawing: the task of a run folder is fixed"),
        (["reproduce", "{run}", "--set", "task=drawing"], "the task of a run folder is fixed"),
        (["reproduce", "{run}", "--set", "mapping.delay_steps=5"],
         "reproduce does not use mapping.*: it reads reproduction.*"),
        (["reproduce", "{run}", "--set", "learning.num_states=6"], "reproduce does not use learning.*"),
        (["learn", "{run}", "--iterations", "1000000000"], "--iterations must be at most 1000"),
    ],
)  # fmt: skip
def test_learn_and_reproduce_refuse_a_set_they_do_not_read(run_folder, run_cli, no_jobs, argv, words):
    before = snapshot(run_folder)
    code, stdout, err = run_cli([a.format(run=run_folder) for a in argv])
    assert words in one_line(code, stdout, err, argv[0])
    assert snapshot(run_folder) == before


@pytest.mark.parametrize(
    "override, words",
    [
        ("reproduction.horizon=1000000000",
         "--set reproduction.horizon=1000000000: key 'reproduction.horizon' must be at most 1000"),
        # The dataset's scenario has k_max 200: the --set breaks k_min < k_max, not the run.
        ("emg.k_min=300", "--set emg.k_min=300: keys 'emg.k_min' < 'emg.k_max' required"),
        ("plant.contact_model=hydroelastc", "key 'plant.contact_model' = 'hydroelastc'"),
    ],
)  # fmt: skip
def test_reproduce_refuses_a_bad_value_before_touching_the_run(run_folder, run_cli, override, words):
    before = snapshot(run_folder)
    code, stdout, err = run_cli(["reproduce", str(run_folder), "--no-replay", "--set", override])
    assert words in one_line(code, stdout, err, "reproduce")
    assert snapshot(run_folder) == before


def test_learn_help_shows_a_key_learn_reads(run_cli):
    code, out, _ = run_cli(["learn", "--help"])
    text = " ".join(out.split())
    assert code == 0 and "learning.num_states=6" in text and "emg.k_max" not in text


def test_the_command_alone_lists_the_commands(run_cli):
    code, out, err = run_cli([])
    assert code == 2 and out == ""
    assert err.startswith("usage: hemg-drake [-h] [--version] COMMAND ...\ncommands:\n")
    for command in ("demo", "demonstrate", "learn", "reproduce", "emg-figure", "export",
                    "import", "teleop", "stability", "sweep"):  # fmt: skip
        assert f"\n  {command} " in err


@pytest.mark.parametrize(
    "package, extra, argv, job",
    [
        ("h5py", "export", ["export", "{run}", "{tmp}/x.hdf5"], None),
        ("pyomyo", "myo", ["demonstrate", "cotter_pin", "--out", "{tmp}/o"],
         ("hemg_drake.emg._myo", "_import_pyomyo")),
        ("pyOpenHaptics", "touchx", ["demonstrate", "cotter_pin", "--out", "{tmp}/o"],
         ("hemg_drake.teleop.devices", "_import_pyopenhaptics")),
    ],
)  # fmt: skip
def test_a_missing_optional_package_is_one_clean_sentence(
    tmp_path, run_folder, run_cli, monkeypatch, package, extra, argv, job
):
    monkeypatch.setitem(sys.modules, package, None)  # not importable
    if job is not None:  # the job imports the device's driver, as a live source would
        import importlib

        module_name, function = job
        importer = getattr(importlib.import_module(module_name), function)
        monkeypatch.setattr(pipeline, "demonstrate", lambda *a, **k: importer())
    code, stdout, err = run_cli([a.format(run=run_folder, tmp=tmp_path) for a in argv])
    message = one_line(code, stdout, err, argv[0])
    assert f"needs the {package} package" in message or f"needs {package}" in message
    assert f"pip install 'hemg-drake[{extra}]'" in message
    assert "needs the optional package the" not in message and "package robomimic" not in message
    assert not (tmp_path / "x.hdf5").exists()


@pytest.mark.parametrize(
    "argv, words",
    [
        (["stability", "cotter_pin", "--delays", "0", "100000", "-o", "{tmp}/s.png"],
         "--delays 100000: at most 500 ms"),
        (["emg-figure", "--seed", "4294967296", "-o", "{tmp}/f.png"],
         "--seed must be at most 4294967295"),
        (["demonstrate", "cotter_pin", "--out", "{tmp}/o", "--seed", "4294967296"],
         "--seed must be at most 4294967295"),
        (["teleop", "cotter_pin", "--out", "{tmp}/o", "--port", "70000"],
         "--port must be at most 65535"),
    ],
)  # fmt: skip
def test_command_line_sizes_are_bounded(tmp_path, run_cli, no_jobs, argv, words):
    code, stdout, err = run_cli([a.format(tmp=tmp_path) for a in argv])
    assert words in one_line(code, stdout, err, argv[0])
    assert list(tmp_path.iterdir()) == []
