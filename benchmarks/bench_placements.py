"""Both tasks at placements never demonstrated: TP-HSMM against the world-frame HSMM (issue 16).

Demonstrations at C placements drawn from a range (``scene.placements``), then, in the Drake
scenes (the whole reproduction diagram: reproducer, CLIK, PD, plant and the task's scene):

- **leave one placement out**: for each demonstrated placement, both models fitted to the
  other C - 1 demonstrations reproduce the task there (the placement is new to them);
- **outside the range**: both models fitted to all C reproduce it at placements beyond it.

Every reproduction is measured against the training demonstrations carried rigidly to its
placement (``hemg_drake.placements.moved_demonstration``), as ``hemg-drake reproduce`` does.
Pin: success (pin out, forces within 1.5x the demonstrated, no overshoot or dip), the
reference's distance from the pull axis when the pull starts (grasp position error), the
angle of its pull from the axis, the peak force. Drawing: strokes, their shape and
placement error (seen from above: the sheet frame's xy, up to its turn). The table goes to
stdout (``docs/placements.md``); ``--figure`` writes ``docs/img/placements.png``.

Run: ``.venv/bin/python benchmarks/bench_placements.py [--tasks cotter_pin drawing]``.
"""

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from hemg_drake.diagrams.reproduction import build_reproduction_diagram, run_reproduction
from hemg_drake.evaluation import task_metrics
from hemg_drake.learning.demos import load_dataset
from hemg_drake.pipeline import demonstrate, fit_model, learning_data, placed_model
from hemg_drake.placements import moved_demonstration, placed, scene_frame, task_frames
from hemg_drake.scenario import load_scenario, shipped_scenario

ROOT = Path(__file__).resolve().parents[1]
# Demonstrated ranges, and the placements beyond them (position in W, yaw in deg).
SETUPS = {
    "cotter_pin": dict(
        overrides=[
            "num_demonstrations=8",
            "scene.placements.position_range=[[0.60,-0.88,0.11],[0.68,-0.80,0.13]]",
            "scene.placements.yaw_range_deg=[-30,30]",
        ],
        outside=[([0.72, -0.86, 0.12], 45.0), ([0.62, -0.74, 0.10], -50.0)],
    ),
    "drawing": dict(
        overrides=[
            "num_demonstrations=4",
            "scene.placements.position_range=[[0.58,-0.72,0.085],[0.62,-0.68,0.095]]",
            "scene.placements.yaw_range_deg=[-10,10]",
        ],
        outside=[([0.62, -0.66, 0.09], 18.0)],
    ),
}


def quiet(line):
    pass


def reproduce_at(scenario, model, demos, frames):
    """Reproduce ``model`` (TP-HSMM: at the scenario's frames) in the scenario's scene;
    metrics against ``demos`` carried from their frames to the scenario's."""
    hsmm = placed_model(model, scenario)
    here = scene_frame(*task_frames(scenario))
    moved = [moved_demonstration(d, scene_frame(*f), here) for d, f in zip(demos, frames)]
    start = np.mean([d.p_WE[0] for d in moved], axis=0)
    duration = float(np.mean([d.time[-1] for d in moved]))
    built = build_reproduction_diagram(scenario, hsmm, start=start)
    result = run_reproduction(built, duration=duration)
    return task_metrics(scenario.task, moved, result), result, moved


MODELS = ("TP-HSMM, scene frame", "TP-HSMM, base and scene", "world HSMM")


def fit_all(scenario, demos, frames):
    data = learning_data(demos, scenario)
    both = scenario.replaced(["learning.task_frames=base_and_scene"])
    return dict(zip(MODELS, (
        fit_model(data, scenario.replaced(["learning.task_frames=scene"]), frames=frames),
        fit_model(data, both, frames=frames),
        fit_model(data, scenario),
    )))  # fmt: skip


def row(task, case, name, metrics):
    if task == "cotter_pin":
        grasp = metrics["grasp_position_error_m"]
        pull = metrics["pull_direction_error_deg"]
        return (
            case, name, str(metrics["success"]), str(metrics["pin_out"]),
            "-" if grasp is None else f"{1e3 * grasp:.1f}",
            "-" if pull is None else f"{pull:.1f}",
            f"{metrics['peak_force_n']:.1f}",
        )  # fmt: skip
    shape = [e for e in metrics["stroke_shape_error_m"] if e is not None]
    where = [e for e in metrics["stroke_placement_error_m"] if e is not None]
    return (
        case, name, str(metrics["success"]), str(metrics["strokes"]),
        " / ".join(f"{1e3 * e:.1f}" for e in shape) or "-",
        " / ".join(f"{1e3 * e:.1f}" for e in where) or "-",
        f"{metrics['peak_force_n']:.1f}",
    )  # fmt: skip


HEADERS = {
    "cotter_pin": ("placement", "model", "success", "pin out", "grasp error (mm)",
                   "pull direction error (deg)", "peak force (N)"),  # fmt: skip
    "drawing": ("placement", "model", "success", "strokes", "shape error (mm)",
                "placement error (mm)", "peak force (N)"),  # fmt: skip
}


def table(task, rows):
    lines = ["| " + " | ".join(HEADERS[task]) + " |", "|" + "---|" * len(HEADERS[task])]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def evaluate(task, work, figure_data):
    setup = SETUPS[task]
    scenario = load_scenario(shipped_scenario(task), overrides=setup["overrides"])
    began = time.perf_counter()
    demonstrate(scenario, work / task, replays=False, progress=quiet)
    demos, _ = load_dataset(work / task / "dataset.npz")
    frames = [d.frames for d in demos]
    print(f"{task}: {len(demos)} demonstrations in {time.perf_counter() - began:.0f} s")
    rows, summary = [], {name: [] for name in MODELS}
    for c, demo in enumerate(demos):
        keep = [i for i in range(len(demos)) if i != c]
        train, train_frames = [demos[i] for i in keep], [frames[i] for i in keep]
        (R, p) = scene_frame(*frames[c])
        yaw = float(np.degrees(np.arctan2(R[1, 0], R[0, 0])))
        here = placed(scenario, p, yaw)
        case = f"in {c + 1}: {np.round(p, 3).tolist()}, {yaw:.0f} deg"
        for name, model in fit_all(scenario, train, train_frames).items():
            metrics, _, _ = reproduce_at(here, model, train, train_frames)
            rows.append(row(task, case, name, metrics))
            summary[name].append(metrics)
        print(f"  {case} done after {time.perf_counter() - began:.0f} s", flush=True)
    models = fit_all(scenario, demos, frames)
    for k, (position, yaw) in enumerate(setup["outside"], start=1):
        here = placed(scenario, position, yaw)
        case = f"out {k}: {position}, {yaw:.0f} deg"
        for name, model in models.items():
            metrics, result, _ = reproduce_at(here, model, demos, frames)
            rows.append(row(task, case, name, metrics))
            if name == MODELS[0] and k == 1:
                figure_data[task] = (demos, result.log, here)
        print(f"  {case} done after {time.perf_counter() - began:.0f} s", flush=True)
    inside = {name: [m["success"] for m in ms] for name, ms in summary.items()}
    print(table(task, rows))
    for name, successes in inside.items():
        print(f"{name}: {sum(successes)}/{len(successes)} successes at the left-out placements")
    print(f"{task}: {time.perf_counter() - began:.0f} s in all (2 shared cores)\n", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=list(SETUPS), choices=list(SETUPS))
    parser.add_argument("--figure", action="store_true", help="write docs/img/placements.png")
    args = parser.parse_args()
    figure_data = {}
    with tempfile.TemporaryDirectory() as work:
        for task in args.tasks:
            evaluate(task, Path(work), figure_data)
    if args.figure and figure_data:
        from hemg_drake.viz.figures import plot_placements, save_figure

        task = "drawing" if "drawing" in figure_data else next(iter(figure_data))
        demos, log, here = figure_data[task]
        path = ROOT / "docs" / "img" / "placements.png"
        save_figure(plot_placements(demos, log, task=task, X_WT=here.X_WT()), path)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
