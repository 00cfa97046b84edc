"""Throughput of ``hemg-drake sweep``'s local backend: the same trials on 1 and 2 workers.

Runs one small sweep (the cotter pin, 2 demonstrations of 4.5 s, learn, reproduce; 4 sEMG
windows x 2 seeds = 8 independent trials, no shared demonstrations) into a temporary
folder, first with one worker (the trials one after another, in one worker process as the
sweep runs them) and then with two, and prints the wall time, the trials per minute and
their ratio (goal on 2 cores: >= 1.8x), with the machine's load average before each run
(the cores are shared: other processes lower the ratio). ``--workers 1 2 4`` picks the
worker counts; ``--seeds`` the number of seeds.
"""

import argparse
import io
import os
import tempfile
import time
from pathlib import Path

from hemg_drake.sweep import run_sweep

SWEEP = """\
scenario: cotter_pin
set: [num_demonstrations=2, learning.n_iter=10]
axes:
  - name: emg.window
    values: [10, 20, 30, 40]
seeds: {seeds}
steps: [demonstrate, learn, reproduce]
metrics: [reproduction.position_rmse_m]
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--seeds", type=int, default=2)
    args = parser.parse_args()
    seeds = [100 * i for i in range(args.seeds)]
    with tempfile.TemporaryDirectory() as root:
        path = Path(root) / "bench.yaml"
        path.write_text(SWEEP.format(seeds=seeds))
        rates, results = {}, {}
        for workers in args.workers:
            load = os.getloadavg()[0]
            began = time.perf_counter()
            records = run_sweep(path, Path(root) / f"w{workers}", workers=workers,
                                stream=io.StringIO())  # fmt: skip
            wall = time.perf_counter() - began
            failed = [r for r in records if r["status"] != "done"]
            if failed:
                raise SystemExit(f"{len(failed)} trial(s) failed: {failed[0]['error']}")
            rates[workers] = 60.0 * len(records) / wall
            results[workers] = [r["metrics"]["reproduction.position_rmse_m"] for r in records]
            mean_trial = sum(r["elapsed_s"] for r in records) / len(records)
            print(f"{workers} worker(s): {len(records)} trials in {wall:.1f} s = "
                  f"{rates[workers]:.1f} trials/min (a trial {mean_trial:.1f} s in its "
                  f"worker; load average before {load:.1f} on {os.cpu_count()} cores)")  # fmt: skip
        base = args.workers[0]
        for workers in args.workers[1:]:
            same = results[workers] == results[base]
            print(f"throughput {workers} vs {base} worker(s): {rates[workers] / rates[base]:.2f}x"
                  f" (goal on 2 cores: >= 1.8x); same numbers: {same}")  # fmt: skip


if __name__ == "__main__":
    main()
