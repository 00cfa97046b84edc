"""hemg-drake sweep under faults (issue 25): Ctrl-C and SIGTERM give one line and 130 / 143
and stop the workers with the sweep; SIGKILL at seeded moments keeps every finished trial and
``--resume`` ends with the uninterrupted run's ``results.csv``, byte for byte; a full disk
gives one line naming the file and leaves nothing partial. Each runs the CLI in a
subprocess (a signal to the sweep alone, as ``kill`` sends it) on tiny drawing trials."""

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# 4 trials of 2 demonstrations of 0.5 s and 3 EM iterations: a few seconds each.
SWEEP = """\
scenario: drawing
set: [num_demonstrations=2, duration=0.5, learning.n_iter=3, learning.num_states=2]
axes:
  - {name: emg.window, values: [10, 30]}
seeds: [3, 10]
steps: [demonstrate, learn]
metrics: [demonstration.tracking_error_m, learn.n_iter]
"""
SEED = 25  # the kills' moments


def _start(path, out, *extra):
    env = {k: v for k, v in os.environ.items() if not k.startswith("HEMG_DRAKE_FAULT")}
    env.update(PYTHONPATH=str(REPO), MPLBACKEND="Agg")
    command = [sys.executable, "-m", "hemg_drake.cli", "sweep", str(path), "--out", str(out),
               "--workers", "2", *extra]  # fmt: skip
    return subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)  # fmt: skip


def _children(pid):
    """The processes whose parent is ``pid`` (from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                found.append(int(entry.name))
    return found


def _running(pids):
    """Those of ``pids`` still running (zombies, awaiting their reaper, do not run)."""
    alive = []
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive.append(pid)
    return alive


def _gone_within(pids, seconds):
    deadline = time.monotonic() + seconds
    while _running(pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return not _running(pids)


def _wait_for(predicate, seconds=120):
    deadline = time.monotonic() + seconds
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.02)
    return predicate()


def _lines(err):
    """stderr without the progress bar's lines."""
    return [line for line in err.splitlines() if not line.startswith("[")]


def _partial(out):
    """What an unfinished trial or cache entry would leave."""
    return sorted(p.name for p in Path(out).rglob("*")
                  if p.name.startswith(".tmp-") or "hemg-drake-new" in p.name
                  or p.name.endswith(".tmp"))  # fmt: skip


def _records(out):
    """Every trial record's bytes; each one must be complete JSON."""
    records = {}
    for folder in sorted((Path(out) / "trials").glob("[!.]*")):
        data = (folder / "trial.json").read_bytes()
        json.loads(data)
        records[folder.name] = data
    return records


@pytest.fixture
def sweep_file(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(SWEEP)
    return path


@pytest.mark.slow
@pytest.mark.parametrize("signum, status, word", [(signal.SIGINT, 130, "interrupted"),
                                                  (signal.SIGTERM, 143, "terminated")])  # fmt: skip
def test_ctrl_c_and_sigterm_stop_the_workers_with_one_line(sweep_file, tmp_path, signum,
                                                           status, word):  # fmt: skip
    out = tmp_path / "out"
    child = _start(sweep_file, out)
    try:
        if signum == signal.SIGINT:  # after a trial finished: it is kept
            assert _wait_for(lambda: list(out.glob("trials/*/trial.json")))
        else:  # while the first trials run: nothing is kept, not even the folder
            assert _wait_for(lambda: list(out.glob("trials/.tmp-*")))
        workers = _children(child.pid)
        assert len(workers) >= 2
        child.send_signal(signum)
        _, err = child.communicate(timeout=60)
    finally:
        child.kill()
    assert child.returncode == status
    # The workers stop with the sweep (not ~10 s later, as they did).
    assert _gone_within(workers, 2.0), _running(workers)
    if signum == signal.SIGINT:
        kept = len(_records(out))
        assert kept >= 1
        assert _lines(err) == [
            f"hemg-drake sweep: interrupted; no partial trial kept; {kept} finished trial(s) "
            f"in {out / 'trials'}: --resume goes on"
        ]
        assert not _partial(out)
    else:
        assert _lines(err) == ["hemg-drake sweep: terminated; no partial output kept"]
        assert not out.exists()


@pytest.mark.slow
@pytest.mark.deep
def test_killed_at_seeded_moments_resume_ends_with_the_same_table(sweep_file, tmp_path):
    reference = tmp_path / "reference"
    began = time.monotonic()
    child = _start(sweep_file, reference)
    child.communicate(timeout=600)
    whole = time.monotonic() - began
    assert child.returncode == 0
    out, rng, killed = tmp_path / "out", random.Random(SEED), 0
    for _ in range(3):
        before = _records(out) if out.exists() else {}
        resume = ["--resume"] if (out / "sweep.json").is_file() else []
        child = _start(sweep_file, out, *resume)
        try:
            child.communicate(timeout=rng.uniform(0.2, 0.6) * whole)
        except subprocess.TimeoutExpired:
            workers = _children(child.pid)
            child.kill()  # SIGKILL: no handler runs
            child.wait()
            killed += 1
            # The workers die with it (PR_SET_PDEATHSIG), so nothing writes on.
            assert _gone_within(workers, 2.0), _running(workers)
            child.communicate(timeout=10)  # the pipes close with the last worker
        after = _records(out)  # every record complete
        assert {name: after[name] for name in before} == before  # finished ones untouched
    assert killed >= 2
    child = _start(sweep_file, out, "--resume")
    _, err = child.communicate(timeout=600)
    assert child.returncode == 0, err
    assert (out / "results.csv").read_bytes() == (reference / "results.csv").read_bytes()
    assert _records(out).keys() == _records(reference).keys() and not _partial(out)


@pytest.fixture
def small_disk(tmp_path):
    """A 300 kB tmpfs (root only; skipped where mount is not allowed)."""
    from tooling.faults import mount_tmpfs

    with mount_tmpfs(tmp_path / "disk", "size=300k") as disk:
        yield disk


@pytest.mark.slow
def test_a_full_disk_gives_one_line_naming_the_file_and_leaves_nothing(sweep_file, small_disk):
    (small_disk / "mine.txt").write_text("a person's file\n")
    (small_disk / "earlier").mkdir()
    (small_disk / "earlier" / "data.csv").write_text("1,2\n")
    before = {p.relative_to(small_disk): p.read_bytes() for p in small_disk.rglob("*")
              if p.is_file()}  # fmt: skip
    out = small_disk / "out"
    child = _start(sweep_file, out)
    _, err = child.communicate(timeout=300)
    assert child.returncode == 2
    (line,) = _lines(err)
    assert line.startswith(f"hemg-drake sweep: error: {out}/") and line.endswith(
        ": No space left on device"
    ), line
    assert ".tmp" not in line and "hemg-drake-new" not in line  # the file's own name
    after = {p.relative_to(small_disk): p.read_bytes() for p in small_disk.rglob("*")
             if p.is_file()}  # fmt: skip
    assert after == before and not out.exists()
