"""hemg-drake sweep: the local backend through the CLI on tiny trials, the sweep file's
checks (every trial's overrides and the metric names before the first trial), the sweep
folder's rules, and the Ray backend's call pattern against a fake ``ray`` module. Signals,
kills and a full disk: ``tests/test_sweep_faults.py``."""

import csv
import json
import sys
import types
from pathlib import Path

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
      bad: [learning.num_states=90]   # too many states for the data: fails at learn
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


def test_every_trial_has_a_row_and_a_failed_one_is_recorded(swept):
    _, out, code = swept
    assert code == 1  # a trial failed
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
            assert "N = 90" in row["error"] and "\n" not in row["error"]
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
    assert main(["sweep", str(path), "--out", str(out), "--resume", "--workers", "1"]) == 1
    assert not (out / "trials" / ".tmp-killed-123").exists()
    captured = capfd.readouterr()
    assert "4/4 done (2 failed)" in captured.err
    # Each failed trial on stderr, the summary and the table's path on stdout.
    failures = [line for line in captured.err.splitlines() if "failed:" in line]
    assert len(failures) == 2 and all("trial window=" in line for line in failures)
    assert not [line for line in captured.out.splitlines() if "failed:" in line]
    assert captured.out.splitlines()[-1].endswith("(4 trials, 2 failed)")
    assert stamps == {t: (out / "trials" / t / "trial.json").stat().st_mtime_ns for t in done}


def test_one_worker_gives_the_same_numbers_as_two(swept, tmp_path):
    path, out, _ = swept
    serial = tmp_path / "serial"
    assert main(["sweep", str(path), "--out", str(serial), "--workers", "1"]) == 1
    numbers = ["demonstration.tracking_error_m", "reproduction.position_rmse_m"]
    two = {r["trial"]: [r[n] for n in numbers] for r in read_table(out / "results.csv")}
    one = {r["trial"]: [r[n] for n in numbers] for r in read_table(serial / "results.csv")}
    assert one == two
    # The table holds no timing: the same bytes however the trials ran.
    assert (serial / "results.csv").read_bytes() == (out / "results.csv").read_bytes()


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
    """Records the call pattern; each task "fails" at once (no simulation)."""

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
                    fake.results[ref] = dict(
                        id=task["id"], labels=task["labels"], seed=task["seed"],
                        overrides=task["overrides"], status="failed", error="fake", metrics={},
                    )  # fmt: skip
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
    path.write_text(
        "scenario: cotter_pin\naxes: [{name: emg.k_min, values: [10, 20]}]\nseeds: [0]\n"
    )
    # Outside a loopback-only namespace a local Ray would bind the machine's address: refused.
    monkeypatch.setattr(sweep.runners, "only_loopback", lambda: False)
    with pytest.raises(ValueError, match="binds this machine's network address"):
        sweep.run_sweep(path, tmp_path / "refused", backend="ray", workers=3)
    assert fake.calls == [] and not (tmp_path / "refused").exists()
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


def _files(folder):
    """Every file under ``folder`` with its bytes."""
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}  # fmt: skip


@pytest.mark.parametrize(
    "axes, words",
    [
        # An unknown key: the trial, the axis, the value, and the keys there are.
        ("- {name: w, keys: [emg.windw], values: [10]}",
         ["trial w=10-seed=0-", "(axis 'w', value '10')", "emg.windw", "EmgConfig has ["]),
        # A bad value of a case.
        ("- {name: r, cases: {ok: [], low: [emg.k_min=-5]}}",
         ["trial r=low-seed=0-", "(axis 'r', case 'low')", "emg.k_min=-5", "must not be negative"]),
        # Not an integer.
        ("- {name: d, keys: [mapping.delay_steps], values: [0, 2.5]}",
         ["(axis 'd', value '2.5')", "mapping.delay_steps", "must be an integer"]),
        # Two axes fine alone, bad together.
        ("- {name: lo, keys: [emg.k_min], values: [10, 150]}\n"
         "  - {name: hi, keys: [emg.k_max], values: [200, 100]}",
         ["trial lo=150-hi=100-seed=0-", "this combination", "'emg.k_min' < 'emg.k_max'"]),
    ],
)  # fmt: skip
def test_a_bad_trial_is_refused_before_any_trial_in_one_line(tmp_path, capfd, axes, words):
    path = tmp_path / "bad.yaml"
    path.write_text(f"scenario: cotter_pin\naxes:\n  {axes}\n")
    assert main(["sweep", str(path), "--out", str(tmp_path / "out")]) == 2
    captured = capfd.readouterr()
    err = captured.err
    assert err.startswith(f"hemg-drake sweep: error: {path}: ") and err.count("\n") == 1
    for word in words:
        assert word in err, (word, err)
    assert not (tmp_path / "out").exists() and captured.out == ""


def test_an_unknown_metric_is_refused_listing_the_known_ones(tmp_path, capfd):
    path = tmp_path / "m.yaml"
    path.write_text("scenario: drawing\nsteps: [demonstrate, learn]\n"
                    "metrics: [learn.n_iter, demonstration.pin_out, reproduction.success]\n")
    assert main(["sweep", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and "key 'metrics'" in err
    assert "unknown metric(s) ['demonstration.pin_out', 'reproduction.success']" in err
    assert "(['reproduction.success'] need more steps" in err
    assert "'demonstration.three_strokes'" in err and "'learn.converged'" in err
    assert not (tmp_path / "out").exists()


def test_the_known_metrics_are_the_ones_a_trial_records(swept):
    # Drift guard: the names a real cotter-pin trial records against the declared ones.
    _, out, _ = swept
    recorded = set()
    for path in (out / "trials").glob("*/trial.json"):
        record = json.loads(path.read_text())
        if record["status"] == "done":
            recorded |= set(record["metrics"])
    steps = ["demonstrate", "learn", "reproduce"]
    assert recorded == set(sweep.known_metrics(["cotter_pin"], steps))


def test_a_folder_the_sweep_did_not_write_is_refused_and_untouched(swept, tmp_path, capfd):
    path, _, _ = swept
    mine = tmp_path / "mine"
    (mine / "trials").mkdir(parents=True)
    (mine / "notes.txt").write_text("a person's notes\n")
    (mine / "trials" / ".tmp-x-1").mkdir()  # even names the sweep would tidy
    before = _files(mine), sorted(p.name for p in mine.rglob("*"))
    for extra in ([], ["--resume"]):
        assert main(["sweep", str(path), "--out", str(mine), *extra]) == 2
        err = capfd.readouterr().err
        assert err == (f"hemg-drake sweep: error: {mine}: holds files hemg-drake sweep did "
                       f"not write (no sweep.json): give a new or empty folder for the sweep\n")
    assert (_files(mine), sorted(p.name for p in mine.rglob("*"))) == before


def test_resume_only_the_same_sweep(swept, tmp_path, capfd):
    path, out, _ = swept
    before = _files(out)
    other = tmp_path / "other.yaml"
    other.write_text(path.read_text().replace("learning.n_iter=3", "learning.n_iter=4"))
    assert main(["sweep", str(other), "--out", str(out), "--resume"]) == 2
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and "was written by another sweep (its 'set' differ)" in err
    assert _files(out) == before
    # Nothing to resume in a new folder: refused, and nothing is left there.
    assert main(["sweep", str(path), "--out", str(tmp_path / "new"), "--resume"]) == 2
    assert "no sweep to resume there (no sweep.json)" in capfd.readouterr().err
    assert not (tmp_path / "new").exists()


def test_two_sweeps_on_one_folder_one_is_refused_naming_the_other(tmp_path, capfd):
    import os
    import signal
    import subprocess
    import time

    path = tmp_path / "slow.yaml"
    path.write_text("scenario: drawing\nset: [num_demonstrations=1, duration=0.5]\n"
                    "steps: [demonstrate]\nmetrics: [demonstration.strokes]\n")  # fmt: skip
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    first = subprocess.Popen(
        [sys.executable, "-m", "hemg_drake.cli", "sweep", str(path), "--out", str(out)],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while not (out / "sweep.json").is_file() and time.monotonic() < deadline:
            time.sleep(0.02)
        assert (out / "sweep.json").is_file()
        for extra in ([], ["--resume"]):
            assert main(["sweep", str(path), "--out", str(out), *extra]) == 2
            err = capfd.readouterr().err
            assert err.count("\n") == 1 and f"(PID {first.pid}) is using it" in err, err
    finally:
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=60)
    assert first.returncode in (0, 130)


def test_a_drawings_completion_is_when_its_third_stroke_ends():
    # Hand-made logs at 100 Hz: ink (|f| 5 N) over [1, 2), [3, 4), [5, 6.5) s, the pen at
    # rest elsewhere: three strokes, the last inked sample at 6.49 s. A log with two: NaN,
    # and the mean completion is over the demonstrations that drew three.
    import math
    from types import SimpleNamespace

    import numpy as np

    from hemg_drake.scenario import load_scenario, shipped_scenario
    from hemg_drake.sweep.trial import demonstration_metrics

    time = np.arange(0, 800) * 0.01

    def demo(spans):
        f_WE = np.zeros((time.size, 3))
        for a, b in spans:
            f_WE[(time >= a - 1e-9) & (time < b - 1e-9), 2] = 5.0
        zeros = np.zeros((time.size, 3))
        return SimpleNamespace(
            time=time, p_WE=zeros, p_MS=zeros, f_WE=f_WE, emg_time=time,
            muscle_activation=np.full(time.size, 0.1), gain=np.full(time.size, 100.0),
        )  # fmt: skip

    scenario = load_scenario(shipped_scenario("drawing"))
    three, two = demo([(1, 2), (3, 4), (5, 6.5)]), demo([(1, 2), (3, 4)])
    record = demonstration_metrics(scenario, [three, two])
    assert record["strokes"] == 2.5 and record["three_strokes"] == 0.5
    assert record["completion_s"] == pytest.approx(6.49)
    assert math.isnan(demonstration_metrics(scenario, [two])["completion_s"])
