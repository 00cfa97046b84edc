"""Cost of the learning and reproduction stages, on the demonstrations `make demo` recorded.

Prints, per task: the HSMM fit with the scenario's learning settings
(``pipeline.fit_model``), building the reproduction diagram (which only builds), running it
(settling the arm included) with and without the scene (wall time and real-time factor),
and the Table II metrics with their cost. Uses runs/TASK/dataset.npz when `make demo` has
written it; otherwise records the scenario's demonstrations into a temporary folder first
(about a minute).
"""

import tempfile
import time
from pathlib import Path

from hemg_drake.diagrams.reproduction import build_reproduction_diagram, run_reproduction
from hemg_drake.evaluation import task_metrics
from hemg_drake.pipeline import TASKS, demonstrate, fit_model, learning_data, load_demonstrations
from hemg_drake.scenario import load_scenario, shipped_scenario

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
    scenario = load_scenario(shipped_scenario(task))
    return demonstrate(scenario, Path(scratch) / task, replays=False, progress=lambda _: None)[0]


def main():
    with tempfile.TemporaryDirectory() as scratch:
        for task in TASKS:
            bench_task(task, dataset_of(task, scratch))


def bench_task(task, dataset):
    """Print the figures of one task."""
    demos, scenario = load_demonstrations(dataset)
    data = learning_data(demos, scenario)
    model, seconds = timed(lambda: fit_model(data, scenario))
    print(f"{task}: HSMM fit N = {model.n_states}, C = {len(data)}, "
          f"T = {len(data[0])}: {seconds:.2f} s ({model.n_iter_} iterations)")  # fmt: skip
    duration = float(demos[0].time[-1])
    for scene in (False, True):
        built, build_seconds = timed(
            lambda scene=scene: build_reproduction_diagram(scenario, model, scene=scene)
        )
        result, seconds = timed(lambda built=built: run_reproduction(built, duration=duration))
        where = "in the scene" if scene else "in free space"
        print(f"  reproduction {where}: built in {build_seconds:.2f} s, {duration:g} s "
              f"simulated in {seconds:.2f} s ({duration / seconds:.1f}x real time)")  # fmt: skip
    metrics, seconds = timed(lambda: task_metrics(task, demos, result))
    print(f"  metrics (DTW alignments of {len(data)} + 1 logs): {seconds:.2f} s: position "
          f"RMSE {1e3 * metrics['position_rmse_m']:.2f} mm, velocity RMSE "
          f"{metrics['velocity_rmse_m_per_s']:.4f} m/s")  # fmt: skip


if __name__ == "__main__":
    main()
