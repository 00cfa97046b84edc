"""Issue 25's probes, as a person meets them at the command line: each answers in one line,
with its exit status, and leaves what the person had untouched."""

import json
import shutil
import signal
import subprocess
import sys
import time

from tooling.faults import SMALL, _env, leftovers, run, snapshot


def copy(base, tmp_path):
    root = tmp_path / "root"
    shutil.copytree(base, root, symlinks=True)
    return root


def one_line(done, status=2):
    assert done.returncode == status, done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
    return done.stderr


def test_a_folder_the_tool_did_not_make_is_refused_not_cleaned(tmp_path):
    mine = tmp_path / "userdir"
    for name in ("metrics.json", "replay_1.html", "placements/p.txt",
                 "start_offset/reproduction.npz", "notes.txt"):  # fmt: skip
        (mine / name).parent.mkdir(parents=True, exist_ok=True)
        (mine / name).write_text(f"a person's {name}\n")
    before = snapshot(mine)
    for argv in (["demonstrate", "cotter_pin", "--out", "userdir", *SMALL],
                 ["teleop", "cotter_pin", "--out", "userdir", "--duration", "0.1", "--port", "0"]):  # fmt: skip
        err = one_line(run(argv, cwd=tmp_path, check=False))
        assert "userdir: holds files hemg-drake did not write (no manifest.json)" in err
        assert snapshot(mine) == before and not leftovers(mine)


def test_import_over_a_run_says_it_replaces_it(base, tmp_path):
    root = copy(base, tmp_path)
    done = run(["import", "demos.hdf5", "--out", "run"], cwd=root)
    assert "replacing" in done.stdout and "of the older run in" in done.stdout
    assert not (root / "run" / "model.npz").exists()  # made from the replaced dataset


def test_a_persons_takes_are_never_replaced_by_a_simulated_run(base, tmp_path):
    root = copy(base, tmp_path)
    before = snapshot(root / "takes")
    for argv in (["demonstrate", "cotter_pin", "--out", "takes", *SMALL],
                 ["import", "demos.hdf5", "--out", "takes"]):  # fmt: skip
        err = one_line(run(argv, cwd=root, check=False))
        assert "holds takes a person recorded (hemg-drake teleop)" in err
    assert snapshot(root / "takes") == before


def test_two_writers_on_one_folder_one_is_refused_naming_the_other(base, tmp_path):
    root = copy(base, tmp_path)
    before = snapshot(root / "run")
    # A first writer that is surely still at work while the others try (then stopped).
    command = [sys.executable, "-m", "hemg_drake.cli", "demonstrate", "cotter_pin", "--out",
               "run", "--set", "num_demonstrations=4", "--set", "duration=30"]  # fmt: skip
    first = subprocess.Popen(command, cwd=root, env=_env({}), stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)  # fmt: skip
    deadline = time.monotonic() + 120
    while not leftovers(root / "run") and time.monotonic() < deadline:
        time.sleep(0.05)
    for argv in (["demonstrate", "cotter_pin", "--out", "run", *SMALL], ["learn", "run"],
                 ["reproduce", "run", "--no-replay"], ["repair", "run"],
                 ["reproduce", "run", "--out", "elsewhere", "--no-replay"]):  # fmt: skip
        err = one_line(run(argv, cwd=root, check=False))
        assert f"PID {first.pid}" in err, err
    assert not (root / "elsewhere").exists()
    assert first.poll() is None  # it was at work throughout
    first.send_signal(signal.SIGINT)
    _, err = first.communicate(timeout=300)
    assert first.returncode == 130, err
    assert snapshot(root / "run") == before


def test_a_dataset_without_its_record_is_repaired_keeping_the_takes(base, tmp_path):
    root = copy(base, tmp_path)
    (root / "takes" / "manifest.json").unlink()  # as a copy by hand between folders loses it
    before = snapshot(root / "takes")
    err = one_line(run(["learn", "takes"], cwd=root, check=False))
    assert "hemg-drake repair takes records the files there" in err
    assert "--out takes" not in err  # no advice that would write over the takes
    # demonstrate is refused there (not a run folder now): the advice never leads to it.
    one_line(run(["demonstrate", "cotter_pin", "--out", "takes", *SMALL], cwd=root, check=False))
    done = run(["repair", "takes"], cwd=root)
    assert "demonstrate: " in done.stdout and "no other file was changed" in done.stdout
    after = snapshot(root / "takes")
    assert {k: v for k, v in after.items() if k != "manifest.json"} == before
    # The folder takes takes again (a second one, so that there is enough to learn from).
    run(["teleop", "cotter_pin", "--out", "takes", "--no-replay", "--replay-inputs",
         "live/inputs_1.npz"], cwd=root)  # fmt: skip
    run(["learn", "takes", "--set", "learning.num_states=3"], cwd=root)
    kept = ("inputs_1.npz",)  # the person's take, byte for byte
    assert all((root / "takes" / name).read_bytes() == before[name] for name in kept)


def test_a_reproduction_in_a_sub_folder_goes_with_the_model_it_came_from(base, tmp_path):
    root = copy(base, tmp_path)
    run(["reproduce", "run", "--out", "run/lqr", "--tracker", "lqr", "--no-replay"], cwd=root)
    manifest = json.loads((root / "run" / "lqr" / "manifest.json").read_text())
    assert set(manifest["reproduce"]["inputs"]) == {"../model.npz", "../dataset.npz"}
    done = run(["demonstrate", "cotter_pin", "--out", "run", "--seed", "9", *SMALL], cwd=root)
    assert not (root / "run" / "lqr").exists()
    assert "replacing" in done.stdout


def test_a_sigkilled_run_leaves_the_folder_usable(base, tmp_path):
    root = copy(base, tmp_path)
    before = snapshot(root / "run")
    command = [sys.executable, "-m", "hemg_drake.cli", "learn", "run"]
    child = subprocess.Popen(command, cwd=root, env=_env({"HEMG_DRAKE_FAULT_AT": "3"}),
                             stderr=subprocess.DEVNULL)  # fmt: skip
    child.wait(timeout=300)
    assert snapshot(root / "run") == before and leftovers(root / "run")
    run(["reproduce", "run", "--no-replay"], cwd=root)  # tidies what was left beside
    assert not leftovers(root / "run")


def test_a_missing_device_package_leaves_a_finished_run_as_it_was(base, tmp_path):
    # Issue 25: a missing LibEMG streamer / MYO package on a re-run wiped the old run.
    root = copy(base, tmp_path)
    before = snapshot(root / "run")
    for out in ("run", "fresh"):
        argv = ["demonstrate", "cotter_pin", "--out", out, "--set", "emg.source=myo", *SMALL]
        err = one_line(run(argv, cwd=root, check=False))
        assert "needs the pyomyo package" in err
    assert snapshot(root / "run") == before and not leftovers(root / "run")
    assert not (root / "fresh").exists()  # no empty --out folder left behind
