"""Cost of the reproduction side of the pipeline, on the run folders `make demo` wrote.

Prints, per task: the HSMM fit, the reproduction's simulation (wall time and real-time
factor, with and without the scene), and the Table II metrics (DTW on the full logs).
Run `make demo` first (it writes runs/cotter_pin/ and runs/drawing/).
"""

import sys
import time
from pathlib import Path

from hemg_drake.diagrams.reproduction import run_reproduction
from hemg_drake.learning.demos import load_dataset, observations
from hemg_drake.learning.hsmm import HSMM
from hemg_drake.pipeline import REG_COVAR, TASKS, task_metrics
from hemg_drake.scenario import parse_scenario

RUNS = Path(__file__).resolve().parents[1] / "runs"


def timed(function):
    start = time.perf_counter()
    value = function()
    return value, time.perf_counter() - start


def main():
    for task in TASKS:
        dataset = RUNS / task / "dataset.npz"
        if not dataset.is_file():
            sys.exit(f"{dataset} not found: run `make demo` first")
        demos, metadata = load_dataset(dataset)
        scenario = parse_scenario(metadata["scenario"])
        data = observations(demos)
        model, seconds = timed(
            lambda: HSMM(scenario.num_states, init="time", reg_covar=REG_COVAR,
                         seed=scenario.seed).fit(data)
        )  # fmt: skip
        print(f"{task}: HSMM fit N = {model.n_states}, C = {len(data)}, "
              f"T = {len(data[0])}: {seconds:.2f} s ({model.n_iter_} iterations)")
        duration = float(demos[0].time[-1])
        for scene in (False, True):
            result, seconds = timed(
                lambda scene=scene: run_reproduction(
                    scenario, model, duration=duration, scene=scene
                )
            )
            where = "in the scene" if scene else "in free space"
            print(f"  reproduction {where}: {duration:g} s simulated in {seconds:.2f} s "
                  f"({duration / seconds:.1f}x real time)")
        _, seconds = timed(lambda: task_metrics(task, demos, result))
        print(f"  metrics (DTW alignments of {len(data)} + 1 logs): {seconds:.2f} s")


if __name__ == "__main__":
    main()
