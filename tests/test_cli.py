"""The `hemg-drake` command line: every mistake in one line before any simulation, --set,
--version, --help with defaults, Ctrl-C. The jobs themselves are tested at small scale in
tests/test_pipeline.py; here the pipeline is replaced wherever a call would simulate."""

import subprocess
import sys
from importlib.metadata import version

import pytest

import hemg_drake.demo as demo
import hemg_drake.pipeline as pipeline


@pytest.fixture
def no_simulation(monkeypatch):
    """Whatever simulates or fits fails the test if it is called: the diagrams' builders
    and runners, and the HSMM fit."""
    import hemg_drake.diagrams.demonstration as demonstration
    import hemg_drake.diagrams.reproduction as reproduction

    def forbid(module, name):
        def called(*args, **kwargs):
            pytest.fail(f"{module.__name__}.{name} was called")

        monkeypatch.setattr(module, name, called)

    for name in ("record_demonstration", "build_demonstration_diagram", "run_demonstration"):
        forbid(demonstration, name)
    for name in ("build_reproduction_diagram", "run_reproduction"):
        forbid(reproduction, name)
    forbid(pipeline, "fit_model")


def assert_one_line_error(code, err, command):
    assert code == 2
    assert "Traceback" not in err
    assert err.count("\n") == 1 and err.startswith(f"hemg-drake {command}: error:"), err


def test_output_paths_are_checked_before_any_simulation(tmp_path, run_cli, no_simulation):
    file = tmp_path / "file"
    file.write_text("not a folder\n")
    cases = [
        (["demo", "--out", str(file)], "demo", f"{file}: exists and is not a folder"),
        (["demo", "--out", str(file / "x")], "demo", f"{file / 'x'}: cannot write there"),
        (["demonstrate", "cotter_pin", "--out", str(file)], "demonstrate", "not a folder"),
        (["demonstrate", "drawing", "--out", str(file / "x")], "demonstrate", "cannot write"),
        (["reproduce", str(tmp_path), "--out", str(file)], "reproduce", "not a folder"),
        (["reproduce", str(tmp_path), "--out", str(file / "x")], "reproduce", "cannot write"),
    ]
    for argv, command, words in cases:
        code, out, err = run_cli(argv)
        assert_one_line_error(code, err, command)
        assert words in err, argv
    assert file.read_text() == "not a folder\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_writable_output_folder_reaches_the_pipeline(tmp_path, run_cli, monkeypatch):
    calls = []
    monkeypatch.setattr(demo, "run_demo", lambda out, **kwargs: calls.append((out, kwargs)))
    out = tmp_path / "new" / "runs"
    code, _, err = run_cli(["demo", "--out", str(out), "--tasks", "drawing", "--no-replay",
                            "--set", "num_demonstrations=2"])  # fmt: skip
    assert (code, err) == (0, "")
    # Checked, not made: the job makes it once its inputs are checked too.
    assert not out.exists()
    ((folder, kwargs),) = calls
    assert str(folder) == str(out) and kwargs["tasks"] == ["drawing"]
    assert kwargs["overrides"] == ["num_demonstrations=2"] and kwargs["replays"] is False
    assert kwargs["placements"] is True  # make demo shows the tasks at new placements too


@pytest.mark.parametrize(
    "argv, command, words",
    [
        (["demo", "--set", "emg.kmax=150"], "demo", ["--set emg.kmax=150", "emg.kmax"]),
        (["demonstrate", "cotter_pin", "--set", "scene.where=1"], "demonstrate",
         ["--set scene.where=1", "scene.where"]),
        (["demonstrate", "cotter_pin", "--set", "emg.k_max"], "demonstrate", ["key=value"]),
        (["demonstrate", "cotter_pin", "--set", "scene.position=[1,2]"], "demonstrate",
         ["scene.position", "3 numbers"]),
        (["demonstrate", "cotter_pin", "--set", "emg=3"], "demonstrate", ["'emg'"]),
        (["demonstrate", "nowhere.yaml"], "demonstrate", ["nowhere.yaml", "not found"]),
        (["demonstrate", "{tmp}"], "demonstrate", ["is a folder"]),
        (["demonstrate", "{tmp}/empty.yaml"], "demonstrate", ["empty"]),
        (["learn", "{run}", "--set", "learning.states=6"], "learn", ["learning.states"]),
        (["learn", "{tmp}/nowhere"], "learn", ["run folder not found"]),
        (["reproduce", "{tmp}/nowhere"], "reproduce", ["run folder not found"]),
        (["reproduce", "{run}"], "reproduce", ["model.npz", "run hemg-drake learn"]),
    ],
)  # fmt: skip
def test_bad_input_is_one_line(
    tmp_path, run_cli, no_simulation, synthetic_run, argv, command, words
):
    (tmp_path / "empty.yaml").write_text("")
    argv = [a.format(tmp=tmp_path, run=synthetic_run) for a in argv]
    if command in ("demo", "demonstrate"):
        argv += ["--out", str(tmp_path / "out")]
    code, _, err = run_cli(argv)
    assert_one_line_error(code, err, command)
    for word in words:
        assert word in err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_learn_set_reaches_the_fit(synthetic_run, run_cli):
    # A real (cheap) fit: the override is applied to the dataset's scenario.
    code, out, err = run_cli(["learn", str(synthetic_run), "--set", "learning.num_states=2",
                              "--iterations", "2"])  # fmt: skip
    assert (code, err) == (0, ""), err
    assert "HSMM N = 2" in out and "2 EM iterations" in out


# Options refused by argparse: one line naming the option and its bound, exit 2, no
# traceback, nothing run.
DEMONSTRATE = ["demonstrate", "cotter_pin", "--out", "{tmp}/o"]
OPTION_MISTAKES = [
    ([*DEMONSTRATE, "--demos", "0"], "--demos must be at least 1"),
    ([*DEMONSTRATE, "--duration", "inf"], "--duration"),
    ([*DEMONSTRATE, "--seed", "-3"], "--seed must not be negative"),
    (["learn", "{tmp}", "--iterations", "0"], "--iterations must be at least 1"),
    (["reproduce", "{tmp}", "--start-offset", "0", "nan", "0"], "--start-offset"),
    (["reproduce", "{tmp}", "--weighting", "backward"], "invalid choice: 'backward'"),
    (["demo", "--tasks", "juggling"], "invalid choice: 'juggling'"),
    (["demonstrate", "--out", "{tmp}/o"], "required: scenario"),
]  # fmt: skip


@pytest.mark.parametrize("argv, words", OPTION_MISTAKES)
def test_bad_option_is_one_line(tmp_path, run_cli, no_simulation, argv, words):
    code, out, err = run_cli([a.format(tmp=tmp_path) for a in argv])
    assert code == 2 and out == "" and "Traceback" not in err
    assert err.count("\n") == 1, err
    assert err.startswith(f"hemg-drake {argv[0]}: error:") and words in err
    assert not (tmp_path / "o").exists()


def test_help_still_shows_the_usage(run_cli):
    code, out, _ = run_cli(["demonstrate", "--help"])
    assert code == 0 and out.startswith("usage: hemg-drake demonstrate")


@pytest.mark.parametrize(
    "command, job",
    [
        (["demo", "--out", "{tmp}"], "run_demo"),
        (["demonstrate", "cotter_pin", "--out", "{tmp}"], "demonstrate"),
        (["learn", "{tmp}"], "learn"),
        (["reproduce", "{tmp}"], "reproduce"),
    ],
)
def test_ctrl_c_is_one_line_and_exit_130(tmp_path, run_cli, monkeypatch, command, job):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(demo if job == "run_demo" else pipeline, job, interrupted)
    try:
        code, _, err = run_cli([a.format(tmp=tmp_path) for a in command])
    except KeyboardInterrupt:
        pytest.fail("the KeyboardInterrupt escaped main()")
    assert code == 130 and "Traceback" not in err
    assert err == f"hemg-drake {command[0]}: interrupted; no partial output kept\n"


@pytest.mark.parametrize("signum, code, said", [("SIGINT", 130, "interrupted"),
                                                ("SIGTERM", 143, "terminated")])
def test_a_signal_that_pybind11_reports_as_a_type_error_is_still_one_line(
    tmp_path, run_cli, monkeypatch, signum, code, said
):
    """Ctrl-C while pybind11 converts a C++ call's numpy arguments: the handler's exception
    comes back as pybind11's TypeError "incompatible function arguments" (seen in a
    demonstration's PD output); it is still the signal: one line and its exit status."""
    import signal

    def signalled_inside_a_call(*args, **kwargs):
        try:
            signal.raise_signal(getattr(signal, signum))  # main()'s handler raises here
        except BaseException:
            raise TypeError("SetFromVector(): incompatible function arguments") from None

    monkeypatch.setattr(pipeline, "learn", signalled_inside_a_call)
    result, _, err = run_cli(["learn", str(tmp_path)])
    assert result == code and err == f"hemg-drake learn: {said}; no partial output kept\n"


def test_a_type_error_without_a_signal_is_not_taken_for_one(tmp_path, run_cli, monkeypatch):
    def failing(*args, **kwargs):
        raise TypeError("a bug")

    monkeypatch.setattr(pipeline, "learn", failing)
    with pytest.raises(TypeError, match="a bug"):
        run_cli(["learn", str(tmp_path)])


def test_demonstrate_options_become_overrides(tmp_path, run_cli, monkeypatch):
    calls = []

    def record(scenario, out, *, replays, progress):
        calls.append((scenario, replays))
        return []

    monkeypatch.setattr(pipeline, "demonstrate", record)
    # A shipped scenario by name; the options and --set, in that order, on top of the file.
    argv = ["demonstrate", "drawing", "--out", str(tmp_path), "--demos", "2", "--duration",
            "1.5", "--seed", "7", "--no-replay", "--set", "emg.k_max=150",
            "--set", "scene.yaw_deg=10"]  # fmt: skip
    code, out, err = run_cli(argv)
    assert (code, err) == (0, "")
    ((scenario, replays),) = calls
    assert scenario.task == "drawing" and replays is False
    assert (scenario.num_demonstrations, scenario.duration, scenario.seed) == (2, 1.5, 7)
    assert scenario.emg.k_max == 150.0 and scenario.scene.yaw_deg == 10.0
    assert scenario.learning.num_states == 18  # the rest is the shipped file's
    assert "drawing: 2 demonstrations of 1.5 s" in out


def test_reproduce_options_become_overrides(tmp_path, run_cli, monkeypatch):
    calls = []
    monkeypatch.setattr(pipeline, "reproduce", lambda run, **kwargs: calls.append(kwargs))
    argv = ["reproduce", str(tmp_path), "--weighting", "spatial", "--restoring-gain", "0.5",
            "--start-offset", "0", "0.01", "0", "--set", "reproduction.settle_time=0.5",
            "--no-replay"]  # fmt: skip
    code, _, err = run_cli(argv)
    assert (code, err) == (0, "")
    (kwargs,) = calls
    assert kwargs["overrides"] == [
        "reproduction.settle_time=0.5", "reproduction.weighting=spatial",
        "reproduction.restoring_gain=0.5",
    ]  # fmt: skip
    assert kwargs["start_offset"] == [0.0, 0.01, 0.0] and kwargs["replay"] is False


def test_version(run_cli):
    code, out, _ = run_cli(["--version"])
    assert code == 0 and out == f"hemg-drake {version('hemg-drake')}\n"


@pytest.mark.parametrize(
    "command, default",
    [
        ("demo", "(default: runs)"),
        ("emg-figure", "(default: 10.0)"),
        ("emg-figure", "(default: fig6.png)"),
        ("reproduce", "(default: [0.0, 0.0, 0.0])"),
    ],
)
def test_help_shows_defaults(run_cli, command, default):
    code, out, _ = run_cli([command, "--help"])
    assert code == 0
    assert default in " ".join(out.split())
    # Options without a default show none.
    assert "(default: None)" not in out and "(default: False)" not in out


def test_console_entry_point_help():
    result = subprocess.run(
        [sys.executable, "-m", "hemg_drake.cli", "demo", "--help"], capture_output=True, text=True
    )
    assert result.returncode == 0 and "--tasks" in result.stdout


def test_closed_stdout_is_tolerated(tmp_path):
    # `hemg-drake ... | head`: the reader goes away; the job still finishes its file.
    out = tmp_path / "fig.png"
    process = subprocess.Popen(
        [sys.executable, "-m", "hemg_drake.cli", "emg-figure", "--duration", "1", "-o", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    process.stdout.close()
    err = process.stderr.read().decode()
    assert process.wait(timeout=60) == 0
    assert "BrokenPipe" not in err and "Traceback" not in err
    assert out.is_file()


def test_a_missing_optional_package_is_one_line_naming_its_extra(tmp_path, run_cli, monkeypatch):
    from hemg_drake import cli

    def needs_h5py(args):
        raise ModuleNotFoundError("No module named 'h5py'", name="h5py")

    monkeypatch.setattr(cli, "export_command", needs_h5py)
    code, out, err = run_cli(["export", str(tmp_path), "--format", "robomimic",
                              str(tmp_path / "x.hdf5")])  # fmt: skip
    assert code == 2 and "Traceback" not in err and err.count("\n") == 1
    assert "needs the optional package h5py: pip install 'hemg-drake[export]'" in err
