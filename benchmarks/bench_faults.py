"""Killed at any moment, no command loses data (issue 25): the full count of SIGKILLs.

    python benchmarks/bench_faults.py [--kills 50] [--seed 7] [--workers 2]

For each command of ``tests/tooling/faults.COMMANDS`` (demonstrate, learn, reproduce, a
teleop take re-driven from its log, import), ``--kills`` kills, half after a seeded random
wall-clock delay and half at a seeded random fault point (every file write and rename, the
hard links of the new version, the swap, the removal of the old version). After each kill
the folder must be byte for byte the earlier run or the new one, and the same command run
again must finish to the new run and leave nothing beside the folder. Prints one row per
command: kills, how many landed before or after the swap, losses, failed next runs. The
seed differs from the tests' (tests/faults uses 2025), so these moments were not tuned on.
"""

import argparse
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from tooling.faults import COMMANDS, Case, kill_once, make_base  # noqa: E402


def _kills(name, base, work, seed, kills):
    import random

    case = Case(name, Path(base), Path(work)).learn_states()
    rng = random.Random(f"{seed}-{name}")
    results = []
    for i in range(kills):
        results.append(kill_once(case, rng, "time" if i % 2 == 0 else "point", i))
        print(f"  {name} {i + 1}/{kills}: {results[-1].how} ({results[-1].detail}): "
              f"{results[-1].state}", flush=True)  # progress, for a long run
    return case, results


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=50, help="kills per command")
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--commands", nargs="+", choices=sorted(COMMANDS), default=sorted(COMMANDS),
                        help="the commands to kill (default: all)")
    args = parser.parse_args()
    began = time.perf_counter()
    with tempfile.TemporaryDirectory() as work:
        base = make_base(Path(work) / "base")
        names = args.commands
        with ProcessPoolExecutor(args.workers) as pool:
            futures = [
                pool.submit(_kills, name, base, Path(work) / name, args.seed, args.kills)
                for name in names
            ]
            outcomes = [future.result() for future in futures]
    print(f"{'command':<12} {'points':>6} {'run (s)':>8} {'kills':>6} {'killed':>7} "
          f"{'earlier':>8} {'new':>5} {'lost':>5} {'next failed':>12}")  # fmt: skip
    total = {"kills": 0, "killed": 0, "lost": 0, "next": 0}
    for case, results in outcomes:
        killed = [r for r in results if r.killed]
        lost = [r for r in results if r.state == "LOST"]
        failed = [r for r in results if not r.next_ok]
        print(f"{case.name:<12} {len(case.points):>6} {case.seconds:>8.1f} {len(results):>6} "
              f"{len(killed):>7} {sum(r.state == 'before' for r in killed):>8} "
              f"{sum(r.state == 'after' for r in killed):>5} {len(lost):>5} {len(failed):>12}")  # fmt: skip
        for r in lost + failed:
            print(f"  {r}")
        total["kills"] += len(results)
        total["killed"] += len(killed)
        total["lost"] += len(lost)
        total["next"] += len(failed)
    print(f"total: {total['killed']} kills landed of {total['kills']} tried (the rest finished "
          f"first), {total['lost']} losses, {total['next']} failed next runs; "
          f"{time.perf_counter() - began:.0f} s")  # fmt: skip
    return 1 if total["lost"] or total["next"] else 0


if __name__ == "__main__":
    sys.exit(main())
