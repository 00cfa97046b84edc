"""hemg-drake sweep: the local backend through the CLI on tiny trials, the sweep file's
checks, and the Ray backend's call pattern against a fake ``ray`` module."""

import csv
import json
import sys
import types

import pytest

from hemg_drake import sweep
from hemg_drake.cli import main

# Tiny trials: 2 demonstrations of 1 s, 3 EM iterations, a short settle before reproducing.
TINY = (
    "[num_demonstrations=2, duration=1.0, learning.n_iter=3, learning.num_states=2, "
    "reproduction.settle_time=0.2]"
)
SWEEP = f"""\
scenario: cotter_pin
set: {TINY}
axes:
  - name: window
    keys: [emg.window]
    values: [10, 30]
  - name: range
    cases:
      paper: []
      bad: [emg.k_min=-5]      # out of range: this trial fails, the sweep goes on
seeds: [3]
metrics: [demonstration.tracking_error_m, demonstration.gain_lag_s, reproduction.position_rmse_m,
          reproduction.success]
"""


def read_table(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """The tiny sweep run once with 2 workers: (sweep file, out folder, exit code)."""
    root = tmp_path_factory.mktemp("sweep")
    path = root / "tiny.yaml"
    path.write_text(SWEEP)
    out = root / "out"
    code = main(["sweep", str(path), "--out", str(out), "--workers", "2"])
    return path, out, code


def test_every_trial_has_a_row_and_a_failed_one_is_recorded(swept, capsys):
    _, out, code = swept
    assert code == 0
    rows = read_table(out / "results.csv")
    assert [(r["window"], r["range"]) for r in rows] == [
        ("10", "paper"), ("10", "bad"), ("30", "paper"), ("30", "bad")
    ]
    for row in rows:
        record = json.loads((out / "trials" / row["trial"] / "trial.json").read_text())
        assert record["status"] == row["status"]
        assert "seed=3" in record["overrides"]
        if row["range"] == "bad":
            assert row["status"] == "failed"
            assert "emg.k_min" in row["error"] and "\n" not in row["error"]
        else:
            assert row["status"] == "done", row["error"]
            assert float(row["reproduction.position_rmse_m"]) < 0.05
            assert 0 <= float(row["demonstration.gain_lag_s"]) <= 0.5
            assert (out / "trials" / row["trial"] / "run" / "model.npz").is_file()
    assert (out / "results.png").stat().st_size > 1000
    # No temporary trial folder is left behind.
    assert not list((out / "trials").glob(".tmp-*"))


def test_resume_skips_finished_trials_and_retries_failed_ones(swept, capfd):
    path, out, _ = swept
    done = [r["trial"] for r in read_table(out / "results.csv") if r["status"] == "done"]
    stamps = {t: (out / "trials" / t / "trial.json").stat().st_mtime_ns for t in done}
    # Without --resume an existing sweep folder is refused in one line.
    assert main(["sweep", str(path), "--out", str(out)]) == 2
    assert "--resume" in capfd.readouterr().err
    # A killed sweep leaves a trial's temporary folder: resume removes it.
    (out / "trials" / ".tmp-killed-123").mkdir()
    assert main(["sweep", str(path), "--out", str(out), "--resume", "--workers", "1"]) == 0
    assert not (out / "trials" / ".tmp-killed-123").exists()
    err = capfd.readouterr().err
    assert "4/4 done (2 failed)" in err
    assert stamps == {t: (out / "trials" / t / "trial.json").stat().st_mtime_ns for t in done}


def test_one_worker_gives_the_same_numbers_as_two(swept, tmp_path):
    path, out, _ = swept
    serial = tmp_path / "serial"
    assert main(["sweep", str(path), "--out", str(serial), "--workers", "1"]) == 0
    numbers = ["demonstration.tracking_error_m", "reproduction.position_rmse_m"]
    two = {r["trial"]: [r[n] for n in numbers] for r in read_table(out / "results.csv")}
    one = {r["trial"]: [r[n] for n in numbers] for r in read_table(serial / "results.csv")}
    assert one == two


def test_trials_of_a_grid_and_one_at_a_time():
    spec = sweep.parse_sweep(
        "scenario: cotter_pin\naxes:\n  - {name: a, values: [1, 2]}\n"
        "  - {name: b, keys: [x.y, x.z], values: [[0, 1], 3]}\nseeds: [0, 10]\n"
    )
    grid = sweep.trials(spec)
    assert len(grid) == 8 and len({t.id for t in grid}) == 8
    assert grid[1].overrides == ["a=1", "x.y=3", "x.z=3", "seed=0"]
    assert grid[0].overrides == ["a=1", "x.y=[0, 1]", "x.z=[0, 1]", "seed=0"]
    spec.design = "one_at_a_time"
    single = sweep.trials(spec)
    assert [t.labels for t in single[:4]] == [{"a": "1"}, {"a": "2"}, {"b": "[0, 1]"}, {"b": "3"}]
    assert len(single) == 8


def test_a_reproduce_only_axis_changes_the_reproduction_not_the_demonstrations():
    text = ("scenario: cotter_pin\naxes:\n  - {name: a, values: [1, 2]}\n"
            "  - {name: world, reproduce_only: true, cases: {plain: [], moved: [w=1]}}\n")  # fmt: skip
    trials = sweep.trials(sweep.parse_sweep(text))
    assert [(t.labels["world"], t.overrides, t.reproduce_overrides) for t in trials[:2]] == [
        ("plain", ["a=1", "seed=0"], []), ("moved", ["a=1", "seed=0"], ["w=1"])]  # fmt: skip
    assert len({t.id for t in trials}) == 4
    # Without reproduce-only overrides a trial keeps the id it had before the option.
    plain = sweep.trials(sweep.parse_sweep("scenario: cotter_pin\naxes:\n  - {name: a, values: [1, 2]}\n"))
    assert trials[0].id.split("-")[-1] == plain[0].id.split("-")[-1]


@pytest.mark.parametrize(
    "text, message",
    [
        ("axes: []\n", "key 'scenario' is required"),
        ("scenario: x\nbogus: 1\n", "unknown key(s) ['bogus']"),
        (
            "scenario: x\naxes: [{name: a, values: [1], bogus: 2}]\n",
            "unknown key(s) ['axes[0].bogus']",
        ),
        ("scenario: x\nseeds: [1, a]\n", "key 'seeds[1]' must be an integer"),
        ("scenario: x\naxes: [{name: a}]\n", "key 'axes[0]' needs either 'values' or 'cases'"),
        ("scenario: x\nsteps: [learn]\n", "key 'steps' must be the first steps"),
        ("scenario: x\ndesign: random\n", "key 'design' = 'random'"),
        ("scenario: x\nsteps: [demonstrate, learn, reproduce, heldout]\n", "key 'heldout'"),
        ("scenario: [x\n", "malformed YAML at line"),
    ],
)
def test_a_bad_sweep_file_is_one_line_naming_the_file_and_the_key(text, message):
    with pytest.raises(ValueError) as error:
        sweep.parse_sweep(text, source="s.yaml")
    assert str(error.value).startswith("s.yaml: ") and message in str(error.value)
    assert "\n" not in str(error.value)


def test_a_bad_base_scenario_fails_before_any_trial(tmp_path, capfd):
    path = tmp_path / "bad.yaml"
    path.write_text("scenario: cotter_pin\nset: [emg.window=0]\n")
    assert main(["sweep", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capfd.readouterr().err.strip()
    assert "bad.yaml: key 'set'" in err and "emg.window" in err and "\n" not in err
    assert not (tmp_path / "out" / "trials").exists()


def test_shipped_sweeps_load(tmp_path):
    shipped = sorted(sweep.SWEEPS.glob("*.yaml"))
    assert any("example" in p.name for p in shipped)
    for path in shipped:
        spec, _, _ = sweep.load_sweep(path)
        assert sweep.trials(spec)


class FakeRay(types.ModuleType):
    """Records the call pattern and runs each task in this process."""

    def __init__(self):
        super().__init__("ray")
        self.calls, self.results = [], {}

    def init(self, **kwargs):
        self.calls.append(("init", kwargs))

    def remote(self, **options):
        self.calls.append(("remote", options))
        fake = self

        def wrap(function):
            class Remote:
                @staticmethod
                def remote(task):
                    fake.calls.append(("submit", task["id"]))
                    ref = len(fake.results)
                    fake.results[ref] = function(task)
                    return ref

            return Remote

        return wrap

    def wait(self, refs, num_returns=1):
        return refs[:num_returns], refs[num_returns:]

    def get(self, ref):
        return self.results[ref]

    def shutdown(self):
        self.calls.append(("shutdown", {}))


def test_ray_backend_call_pattern_with_a_fake_ray(tmp_path, monkeypatch):
    fake = FakeRay()
    monkeypatch.setitem(sys.modules, "ray", fake)
    path = tmp_path / "fails.yaml"
    # Trials that fail at once (out of range): the call pattern without any simulation.
    path.write_text(
        "scenario: cotter_pin\naxes: [{name: emg.k_min, values: [-1, -2]}]\nseeds: [0]\n"
    )
    # Outside a loopback-only namespace a local Ray would bind the machine's address: refused.
    monkeypatch.setattr(sweep.runners, "only_loopback", lambda: False)
    with pytest.raises(ValueError, match="binds this machine's network address"):
        sweep.run_sweep(path, tmp_path / "refused", backend="ray", workers=3)
    assert fake.calls == []
    monkeypatch.setattr(sweep.runners, "only_loopback", lambda: True)
    records = sweep.run_sweep(path, tmp_path / "out", backend="ray", workers=3)
    assert [r["status"] for r in records] == ["failed", "failed"]
    (_, init), (_, options) = fake.calls[0], fake.calls[1]
    assert init["_node_ip_address"] == "127.0.0.1" and init["include_dashboard"] is False
    assert init["num_cpus"] == 3 and init["object_store_memory"] <= 100 * 2**20
    assert init["runtime_env"]["env_vars"]["NUMBA_NUM_THREADS"] == "1"
    assert options["num_cpus"] == 1
    assert [c[0] for c in fake.calls].count("submit") == 2 and fake.calls[-1][0] == "shutdown"
    fake.calls.clear()
    sweep.run_sweep(path, tmp_path / "joined", backend="ray", address="127.0.0.1:6379")
    assert fake.calls[0][1]["address"] == "127.0.0.1:6379"
    assert "_node_ip_address" not in fake.calls[0][1]


def test_progress_bar_counts_and_time_left():
    import io

    stream = io.StringIO()
    bar = sweep.Progress(4, 2, stream)
    bar.update("done")
    bar.update("failed")
    lines = stream.getvalue().splitlines()
    assert lines[-1].startswith("[############------------] 2/4 done (1 failed), 2 running")
    assert lines[-1].endswith("left")
