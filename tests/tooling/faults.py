"""Fault injection: kill a ``hemg-drake`` command with SIGKILL and check what it leaves.

A *case* is a command run on a folder holding a complete earlier run. The command is run
once uninterrupted (on a copy) to learn the new complete state and its fault points; then on
fresh copies it is killed, either after a seeded random wall-clock delay or at a seeded
random fault point (``hemg_drake.fileio.fault_point``: every file write and rename, the
swap of a run folder's versions). After each kill the folder must be byte for byte either
the earlier run or the new one, and the next command must work (and tidy what was left).

Used by ``tests/faults`` (a few kills per command) and ``benchmarks/bench_faults.py`` (the
full count).
"""

import contextlib
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
# Small settings: the state at stake is the folder, not the simulation.
SMALL = ["--set", "num_demonstrations=2", "--set", "duration=0.6"]


def snapshot(folder):
    """Every file under ``folder`` by relative path, with its bytes ({} if missing)."""
    folder = Path(folder)
    if not folder.exists():
        return {}
    return {
        str(p.relative_to(folder)): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def leftovers(folder):
    """What a stage left beside ``folder`` (its versions being built or replaced)."""
    folder = Path(folder)
    return sorted(p.name for p in folder.parent.glob(f".{folder.name}.hemg-drake-*"))


@contextlib.contextmanager
def mount_tmpfs(folder, options):
    """Mount a tmpfs with ``options`` (e.g. "size=32m") at the folder ``folder`` (made) for
    the block, then unmount it: needs root. Where mount is refused the test skips; under
    ``.ci/run`` as root (HEMG_DRAKE_MOUNT_TESTS=1) it fails instead."""
    import pytest

    Path(folder).mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)],
                          capture_output=True, text=True)  # fmt: skip
    if done.returncode != 0:
        reason = f"cannot mount a tmpfs here: {done.stderr.strip()[:80]}"
        if os.environ.get("HEMG_DRAKE_MOUNT_TESTS") == "1":
            pytest.fail(reason + " (HEMG_DRAKE_MOUNT_TESTS=1: .ci/run runs these as root)")
        pytest.skip(reason)
    try:
        yield Path(folder)
    finally:
        subprocess.run(["umount", str(folder)], check=True)


def run(argv, *, cwd, env=None, check=True):
    """``hemg-drake argv`` in a subprocess; returns it completed."""
    command = [sys.executable, "-m", "hemg_drake.cli", *argv]
    done = subprocess.run(command, cwd=cwd, env=_env(env), capture_output=True, text=True)
    if check and done.returncode != 0:
        raise AssertionError(f"{' '.join(argv)} failed ({done.returncode}): {done.stderr}")
    return done


def _env(extra):
    env = dict(os.environ, PYTHONPATH=str(REPO), MPLBACKEND="Agg")
    env.pop("HEMG_DRAKE_FAULT_AT", None)
    env.pop("HEMG_DRAKE_FAULT_LOG", None)
    env.pop("HEMG_DRAKE_FAULT_ERRNO", None)
    env.update(extra or {})
    return env


def make_base(root):
    """Earlier runs under ``root``: ``run/`` (demonstrated, learnt, reproduced), ``takes/``
    (one take re-driven from a logged one) and an exported ``demos.hdf5``."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    run(["demonstrate", "cotter_pin", "--out", "run", "--seed", "3", *SMALL], cwd=root)
    run(["learn", "run", "--set", "learning.num_states=4"], cwd=root)
    run(["reproduce", "run", "--no-replay"], cwd=root)
    run(["teleop", "cotter_pin", "--out", "live", "--port", "0", "--no-replay", "--no-wait",
         "--duration", "0.3"], cwd=root)  # fmt: skip
    run(["teleop", "cotter_pin", "--out", "takes", "--no-replay",
         "--replay-inputs", "live/inputs_1.npz"], cwd=root)  # fmt: skip
    run(["export", "run", "demos.hdf5"], cwd=root)
    return root


# Each command, the folder it writes (relative to the case's root) and its arguments.
COMMANDS = {
    "demonstrate": ("run", ["demonstrate", "cotter_pin", "--out", "run", "--seed", "5", *SMALL]),
    "learn": ("run", ["learn", "run", "--set", "learning.num_states=3"]),
    "reproduce": ("run", ["reproduce", "run", "--tracker", "lqr"]),
    "teleop": ("takes", ["teleop", "cotter_pin", "--out", "takes", "--no-replay",
                         "--replay-inputs", "live/inputs_1.npz"]),
    "import": ("run", ["import", "demos.hdf5", "--out", "run"]),
}  # fmt: skip


@dataclass
class Case:
    """One command on a copy of the base runs: its states before and after, its fault points
    and its uninterrupted wall time."""

    name: str
    base: Path
    work: Path
    before: dict = field(default_factory=dict)
    after: dict = field(default_factory=dict)
    points: list = field(default_factory=list)
    seconds: float = 0.0

    @property
    def folder(self):
        return COMMANDS[self.name][0]

    @property
    def argv(self):
        return COMMANDS[self.name][1]

    def fresh(self, label):
        """A copy of the base runs to run on."""
        root = self.work / label
        shutil.copytree(self.base, root, symlinks=True)
        return root

    def learn_states(self):
        root = self.fresh("reference")
        self.before = snapshot(root / self.folder)
        log = root / "faults.log"
        began = time.perf_counter()
        run(self.argv, cwd=root, env={"HEMG_DRAKE_FAULT_LOG": str(log)})
        self.seconds = time.perf_counter() - began
        self.after = snapshot(root / self.folder)
        self.points = log.read_text().splitlines()
        if self.after == self.before:
            raise AssertionError(f"{self.name}: the command changed nothing; no case to test")
        shutil.rmtree(root)
        return self


@dataclass
class Kill:
    """What one kill left: ``state`` is "before", "after" or "LOST"."""

    case: str
    how: str
    killed: bool
    state: str
    leftovers: list
    next_ok: bool = True
    detail: str = ""


def kill_once(case, rng, how, index, *, check_next=True):
    """Run ``case`` on a fresh copy and kill it (``how``: "time" or "point"); check the state."""
    root = case.fresh(f"{how}-{index}")
    env = {}
    if how == "point":
        point = rng.randrange(1, len(case.points) + 1)
        env["HEMG_DRAKE_FAULT_AT"] = str(point)
        detail = case.points[point - 1]
    command = [sys.executable, "-m", "hemg_drake.cli", *case.argv]
    child = subprocess.Popen(command, cwd=root, env=_env(env), stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)  # fmt: skip
    if how == "time":
        delay = rng.uniform(0.0, case.seconds)
        detail = f"after {delay:.2f} s of {case.seconds:.2f} s"
        try:
            child.wait(timeout=delay)
        except subprocess.TimeoutExpired:
            child.send_signal(signal.SIGKILL)
    child.communicate()
    killed = child.returncode == -signal.SIGKILL
    state = snapshot(root / case.folder)
    verdict = "before" if state == case.before else "after" if state == case.after else "LOST"
    result = Kill(case.name, how, killed, verdict, leftovers(root / case.folder), detail=detail)
    if check_next:
        again = run(case.argv, cwd=root, check=False)
        # From the earlier run the next one makes the new run; after a finished take,
        # teleop adds one more take (it appends), so only its success is checked.
        same = verdict == "before" or case.name != "teleop"
        result.next_ok = (
            again.returncode == 0
            and (not same or snapshot(root / case.folder) == case.after)
            and not leftovers(root / case.folder)
        )
        if not result.next_ok:
            result.detail += f"; next run: {again.returncode} {again.stderr.strip()[-300:]}"
    shutil.rmtree(root)
    return result


def kill_many(case, seed, *, times, points, check_next=True):
    """``times`` wall-clock kills and ``points`` fault-point kills of ``case`` (seeded)."""
    rng = random.Random(f"{seed}-{case.name}")
    results = []
    for how, count in (("time", times), ("point", points)):
        for index in range(count):
            results.append(kill_once(case, rng, how, index, check_next=check_next))
    return results
