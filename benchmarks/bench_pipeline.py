"""Cost of the reproduction side of the pipeline, on the demonstrations `make demo` recorded.

Prints, per task: the HSMM fit with the pipeline's settings (``pipeline.fit_model``), the
reproduction's simulation with its weighting and attractor (wall time and real-time factor,
with and without the scene; the scene's includes settling the arm at the start), and the
Table II metrics (DTW on the full logs) with their cost.
Uses runs/TASK/dataset.npz when `make demo` has written it; otherwise records the
scenario's demonstrations into a temporary folder first (about a minute).
"""

import tempfile
import time
from pathlib import Path

from hemg_drake.diagrams.demonstration import record_demonstrations
from hemg_drake.diagrams.reproduction import run_reproduction
from hemg_drake.learning.demos import load_dataset
from hemg_drake.pipeline import (
    DEFAULT_WEIGHTING,
    RESTORING_GAIN,
    SCENARIOS_DIR,
    TASKS,
    fit_model,
    learning_data,
    task_metrics,
)
from hemg_drake.scenario import load_scenario, parse_scenario

RUNS = Path(__file__).resolve().parents[1] / "runs"


def timed(function):
    start = time.perf_counter()
    value = function()
    return value, time.perf_counter() - start


def dataset_of(task, scratch):
    """runs/TASK/dataset.npz, or a fresh recording of the scenario in ``scratch``."""
    dataset = RUNS / task / "dataset.npz"
    if dataset.is_file():
        return dataset
    print(f"{task}: no {dataset}; recording the scenario's demonstrations first")
    scenario = load_scenario(SCENARIOS_DIR / f"{task}.yaml")
    return record_demonstrations(scenario, Path(scratch) / task, replays=False)[0]


def main():
    with tempfile.TemporaryDirectory() as scratch:
        for task in TASKS:
            bench_task(task, dataset_of(task, scratch))


def bench_task(task, dataset):
    """Print the figures of one task."""
    demos, metadata = load_dataset(dataset)
    scenario = parse_scenario(metadata["scenario"])
    data = learning_data(demos, scenario)
    model, seconds = timed(lambda: fit_model(data, scenario))
    print(f"{task}: HSMM fit N = {model.n_states}, C = {len(data)}, "
          f"T = {len(data[0])}: {seconds:.2f} s ({model.n_iter_} iterations)")
    duration = float(demos[0].time[-1])
    for scene in (False, True):
        result, seconds = timed(
            lambda scene=scene: run_reproduction(
                scenario,
                model,
                duration=duration,
                weighting=DEFAULT_WEIGHTING,
                restoring_gain=RESTORING_GAIN,
                scene=scene,
            )
        )
        where = "in the scene" if scene else "in free space"
        print(f"  reproduction {where}: {duration:g} s simulated in {seconds:.2f} s "
              f"({duration / seconds:.1f}x real time)")
    metrics, seconds = timed(lambda: task_metrics(task, demos, result))
    print(f"  metrics (DTW alignments of {len(data)} + 1 logs): {seconds:.2f} s: position "
          f"RMSE {1e3 * metrics['position_rmse_m']:.2f} mm, velocity RMSE "
          f"{metrics['velocity_rmse_m_per_s']:.4f} m/s")


if __name__ == "__main__":
    main()
