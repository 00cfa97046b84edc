"""The full demo (``make demo``): the three stages of :mod:`hemg_drake.pipeline` for both
shipped scenarios, from the demonstrated start and from others, and at new placements."""

import contextlib
import json
import time
from pathlib import Path

import numpy as np

from hemg_drake.fileio import write_text_atomic
from hemg_drake.pipeline import (
    TASKS,
    demonstrate,
    demonstrate_heldout,
    learn,
    load_demonstrations,
    reproduce,
)
from hemg_drake.run_folder import RunFolder


# run_demo(placements=True): each task demonstrated at placements drawn from a modest range
# around its shipped pose, then reproduced at a pose beyond it (position m, yaw deg).
PLACEMENT_DEMOS = {
    "cotter_pin": (
        ["scene.placements.position_range=[[0.622,-0.857,0.11],[0.662,-0.817,0.13]]",
         "scene.placements.yaw_range_deg=[-20,20]"],
        ([0.66, -0.80, 0.12], 25.0),
    ),
    "drawing": (
        ["scene.placements.position_range=[[0.585,-0.715,0.085],[0.615,-0.685,0.095]]",
         "scene.placements.yaw_range_deg=[-8,8]"],
        ([0.615, -0.685, 0.09], 12.0),
    ),
}  # fmt: skip


def placement_demo(scenario, run_dir, *, replays=True, progress=print):
    """Demonstrate ``scenario`` at the placements of ``PLACEMENT_DEMOS`` (its task), learn the
    TP-HSMM and reproduce at the new pose; writes the stages' outputs and
    ``placements.png`` (demonstrations grey, the reproduction red, from above).

    Returns
    -------
    dict, run name ("TASK (new placement)") -> metrics.
    """
    from hemg_drake.diagrams.reproduction import ReproductionLog
    from hemg_drake.viz.run_figures import write_placements_figure

    ranges, (position, yaw) = PLACEMENT_DEMOS[scenario.task]
    folder = Path(run_dir)
    demonstrate(scenario.replaced(ranges), folder, replays=False, progress=progress)
    learn(folder, progress=progress)
    values = ",".join(repr(float(v)) for v in position)
    new = [f"scene.position=[{values}]", f"scene.yaw_deg={float(yaw)!r}"]
    # Fresh demonstrations at the new pose: what a person would have shown there.
    heldout = _heldout(scenario.replaced(new), folder, progress)
    metrics = reproduce(folder, overrides=new, replay=replays, heldout=heldout, progress=progress)
    demos, recorded = load_demonstrations(folder / "dataset.npz")
    with np.load(folder / "reproduction.npz") as arrays:
        log = ReproductionLog(**{name: arrays[name] for name in arrays.files})
    X_WT = recorded.replaced(new).X_WT()
    # The figure joins the reproduce stage's record (a new version of the folder, as always).
    with RunFolder.output(folder).transaction("reproduce", keep_own=True) as run:
        figure = run / "placements.png"
        write_placements_figure(demos, log, scenario.task, X_WT, figure)
        written = [run / name for name in run.manifest()["reproduce"]["files"]]
        run.finish("reproduce", [*written, figure], inputs=[run.model, run.dataset])
    progress(f"wrote {folder / 'placements.png'}")
    return {f"{scenario.task} (new placement)": metrics}


def _heldout(scenario, run_dir, progress):
    """The run's fresh demonstrations (``reproduction.num_heldout``; None without)."""
    if not scenario.reproduction.num_heldout:
        return None
    began = time.perf_counter()
    folder = demonstrate_heldout(scenario, run_dir, progress=progress)
    progress(f"fresh demonstrations (seeds {scenario.reproduction.heldout_seed}-"
             f"{scenario.reproduction.heldout_seed + scenario.reproduction.num_heldout - 1}) "
             f"in {folder}/: {time.perf_counter() - began:.0f} s")  # fmt: skip
    return folder


def run_demo(
    out_dir="runs", *, tasks=TASKS, overrides=(), replays=True, placements=False, progress=print
):  # fmt: skip
    """The full demo: for each task, demonstrate, learn, reproduce (from the demonstrated
    start and from each of ``reproduction.start_offsets``), draw and measure.

    Per task, ``out_dir/TASK/`` gets the demonstrate, learn and reproduce outputs, the
    fresh demonstrations every reproduction is scored against (``heldout/``, the scenario's
    ``reproduction.num_heldout`` from ``reproduction.heldout_seed``), one more
    reproduction per start offset in ``start_offset/`` (``start_offset_<i>/`` for more than
    one), and the diagrams. ``out_dir/metrics.json`` gathers the metrics; the table is
    printed.

    Parameters
    ----------
    out_dir : path-like
    tasks : sequence of task names (the shipped scenarios)
    overrides : sequence of str, ``key=value`` changes for every task's scenario (e.g.
        ``"num_demonstrations=2"`` for small-scale runs).
    replays : bool, write the HTML replays.
    placements : bool
        Also demonstrate each task at several placements and reproduce it at a new one
        (:func:`placement_demo`, in ``out_dir/TASK/placements/``).
    progress : callable taking one line of text.

    Returns
    -------
    dict, run name -> metrics.
    """
    from hemg_drake.evaluation import format_metrics
    from hemg_drake.scenario import load_scenario, shipped_scenario

    from hemg_drake.folder_lock import folder_lock

    unknown = [task for task in tasks if task not in TASKS]
    if unknown or not tasks:
        raise ValueError(f"tasks must be among {TASKS}, got {list(tasks)}")
    out_dir = Path(out_dir)
    scenarios = {task: load_scenario(shipped_scenario(task), overrides=overrides) for task in tasks}
    summary = out_dir / "metrics.json"
    made = not out_dir.exists()
    out_dir.mkdir(parents=True, exist_ok=True)
    try:
        with folder_lock(out_dir):
            _check_demo_summary(out_dir, summary)
            results = _run_demo(scenarios, out_dir, replays, placements, progress)
            # The folder holds the tasks' runs and other folders: its manifest lists only
            # the summary (it is not a run folder of its own).
            write_text_atomic(summary, json.dumps(results, indent=2) + "\n")
            RunFolder(out_dir).finish("demo", [summary])
    except BaseException:
        if made:
            with contextlib.suppress(OSError):
                out_dir.rmdir()
        raise
    progress(format_metrics(results))
    progress(f"wrote {summary}")
    return results


def _check_demo_summary(out_dir, summary):
    """Refuse to overwrite a ``metrics.json`` that no demo recorded writing."""
    from hemg_drake.run_folder import MANIFEST

    listed = RunFolder(out_dir).manifest().get("demo", {}).get("files", {})
    if summary.exists() and "metrics.json" not in listed:
        raise ValueError(
            f"{summary}: not written by hemg-drake demo (no demo in {out_dir / MANIFEST} "
            "lists it), and the demo writes that name: move it away or choose another --out"
        )


def _run_demo(scenarios, out_dir, replays, placements, progress):
    results, began = {}, time.perf_counter()
    for task, scenario in scenarios.items():
        run_dir = out_dir / task
        progress(
            f"== {task}: {scenario.num_demonstrations} demonstrations of {scenario.duration:g} s, "
            f"N = {scenario.learning.num_states} states -> {run_dir}/"
        )
        for path in demonstrate(scenario, run_dir, replays=replays, progress=progress):
            progress(f"wrote {path}")
        heldout = _heldout(scenario, run_dir, progress)
        learn(run_dir, diagrams=True, progress=progress)
        results[task] = reproduce(run_dir, replay=replays, heldout=heldout, progress=progress)
        offsets = scenario.reproduction.start_offsets
        for i, offset in enumerate(offsets):
            name = "start_offset" if len(offsets) == 1 else f"start_offset_{i + 1}"
            distance = 100 * float(np.linalg.norm(offset))
            results[f"{task} (start {distance:.0f} cm away)"] = reproduce(
                run_dir, start_offset=offset, out_dir=run_dir / name, replay=False,
                heldout=heldout, progress=progress,
            )  # fmt: skip
        if placements:
            results.update(
                placement_demo(scenario, run_dir / "placements", replays=replays, progress=progress)
            )
        progress(f"== {task} done after {time.perf_counter() - began:.0f} s")
    return results
