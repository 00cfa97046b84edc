"""Killed at any moment, a command leaves its folder as the earlier run or the new one, byte
for byte, and the next command works (issue 25). A seeded few kills per command here; the
full count (>= 250) is ``benchmarks/bench_faults.py``."""

import signal
import subprocess
import sys
import time

import pytest

from tooling.faults import COMMANDS, Case, _env, kill_many, leftovers, snapshot

SEED = 2025  # the kills' moments; the benchmark draws others


# make test kills learn, teleop and import (the run's writes go through the same fileio);
# demonstrate and reproduce are .ci/run's deep step (make test keeps under 10 minutes).
DEEP = {"demonstrate", "reproduce"}


@pytest.mark.slow
@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=pytest.mark.deep) if n in DEEP else n for n in sorted(COMMANDS)]
)
def test_a_killed_command_leaves_the_earlier_run_or_the_new_one(base, tmp_path, name):
    case = Case(name, base, tmp_path).learn_states()
    assert len(case.points) >= 4, case.points  # the writes and the swap are fault points
    assert any("swapped" in point for point in case.points)
    results = kill_many(case, SEED, times=1, points=1)
    for result in results:
        assert result.state in ("before", "after"), result
        assert result.next_ok, result
    assert any(r.killed for r in results)


@pytest.mark.deep
def test_a_kill_at_each_moment_of_the_swap(base, tmp_path):
    # Every fault point from the new version's first file to the end, for one command.
    import random

    from tooling.faults import kill_once

    case = Case("learn", base, tmp_path).learn_states()
    first = next(i for i, p in enumerate(case.points) if "staging made" in p)

    class Fixed(random.Random):
        def __init__(self, point):
            super().__init__(0)
            self.point = point

        def randrange(self, start, stop):
            return self.point

    for point in range(first + 1, len(case.points) + 1, 4):
        result = kill_once(case, Fixed(point), "point", point, check_next=False)
        assert result.killed and result.state in ("before", "after"), result


@pytest.mark.parametrize("signum, status, word", [(signal.SIGINT, 130, "interrupted"),
                                                  (signal.SIGTERM, 143, "terminated")])  # fmt: skip
def test_ctrl_c_and_sigterm_give_one_line_and_keep_the_earlier_run(base, tmp_path, signum,
                                                                   status, word):  # fmt: skip
    case = Case("demonstrate", base, tmp_path)
    root = case.fresh("signal")
    before = snapshot(root / "run")
    command = [sys.executable, "-m", "hemg_drake.cli", *COMMANDS["demonstrate"][1]]
    child = subprocess.Popen(command, cwd=root, env=_env({}), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)  # fmt: skip
    # Once it has begun writing its new version (the first demonstration is simulating).
    deadline = time.monotonic() + 120
    while not leftovers(root / "run") and time.monotonic() < deadline:
        time.sleep(0.05)
    child.send_signal(signum)
    _, err = child.communicate(timeout=120)
    assert child.returncode == status
    assert err == f"hemg-drake demonstrate: {word}; no partial output kept\n"
    assert snapshot(root / "run") == before and not leftovers(root / "run")
