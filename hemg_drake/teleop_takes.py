"""A person's takes in a run folder: where a take's inputs were active (its idle lead-in and
lead-out are trimmed on save), and the ``hemg-drake takes`` command that lists and removes
takes.

A take is kept only when the person says so at the page (:mod:`hemg_drake.teleop_session`);
once kept, it is one demonstration of ``dataset.npz`` with its raw inputs ``inputs_<c>.npz``
and its replay ``replay_<c>.html``. Removing take k writes the folder's next version through
:meth:`~hemg_drake.run_folder.RunFolder.transaction` (nothing half-written): the dataset
without it, the later takes' files renumbered, the figures redrawn; the model and
reproductions made from the older dataset go with it, as when a take is added.
"""

import dataclasses as dc
import math
import os
import shutil

import numpy as np

# Kept before the first and after the last active input (s): the arm at rest before the
# person starts, and settling after they stop (the virtual hand's 300 N/m settles the
# stylus within about 0.3 s).
LEAD_IN, LEAD_OUT = 0.2, 1.0


def active_samples(master, rows):
    """Which input samples move something: after which the stylus target or the activation
    changed (by the master's own law, :meth:`BrowserMaster.targets`: a keyboard set-point
    still being reached at the keyboard's speed, a stick beyond its dead zone, the trigger).

    Parameters
    ----------
    master : BrowserMaster (float), the take's (its start, workspace, speeds).
    rows : array, shape (N, len(COLUMNS)), an inputs log's rows.

    Returns
    -------
    array of bool, shape (N,); sample 0 is never active (nothing came before it).
    """
    p_T, activation = master.targets(rows)
    active = np.zeros(len(p_T), dtype=bool)
    if len(p_T) >= 2:
        moved = np.any(np.diff(p_T, axis=0) != 0.0, axis=1)
        active[1:] = moved | (np.diff(activation) != 0.0)
    return active


def input_span(master, times, rows, end_time):
    """The part of a take to keep: (t_start, t_end) in s, from ``LEAD_IN`` before the first
    active input sample to ``LEAD_OUT`` after the last (within [0, end_time]); None when no
    input ever moved anything (an empty take)."""
    active = np.flatnonzero(active_samples(master, rows))
    if len(active) == 0:
        return None
    times = np.asarray(times, dtype=float)
    first, last = times[active[0]], times[active[-1]]
    return max(0.0, first - LEAD_IN), min(float(end_time), last + LEAD_OUT)


def trim_demonstration(demo, t_start, t_end, *, emg_period):
    """``demo`` between ``t_start`` and ``t_end`` (s), its clock restarted at 0.

    The logged samples kept are those at t_start' <= t <= t_end, t_start' the first sample
    at or after t_start; the sEMG samples those from t_start' on (with ``emg_period``
    dividing the log times, sample k still falls at k emg_period).
    """
    keep = (demo.time >= t_start - 1e-9) & (demo.time <= t_end + 1e-9)
    index = np.flatnonzero(keep)
    if len(index) < 2:
        raise ValueError(f"a take trimmed to {t_start:.2f}-{t_end:.2f} s keeps under 2 samples")
    i0, i1 = index[0], index[-1] + 1
    t0 = float(demo.time[i0])
    first = int(round(t0 / emg_period))
    e1 = min(len(demo.emg), int(math.floor((float(demo.time[i1 - 1]) + 1e-9) / emg_period)) + 1)
    changes = {}
    for field in dc.fields(demo):
        value = getattr(demo, field.name)
        if field.name in ("seed", "frame_A", "frame_b") or value is None:
            continue
        if field.name in ("emg", "muscle_activation"):
            changes[field.name] = value[first:e1]
        elif field.name == "emg_time":
            changes[field.name] = value[first:e1] - first * emg_period
        elif field.name == "time":
            changes[field.name] = value[i0:i1] - t0
        else:
            changes[field.name] = value[i0:i1]
    return dc.replace(demo, **changes)


def template_strokes(plan):
    """The plan's pen-down strokes: a list of (k, 3) polylines (its waypoints; the plan runs
    straight between them)."""
    strokes, current = [], None
    for i, down in enumerate(plan.pen_down):
        if down:
            current = [plan.points[i]] if current is None else current
            current.append(plan.points[i + 1])
        elif current is not None:
            strokes.append(np.array(current))
            current = None
    if current is not None:
        strokes.append(np.array(current))
    return strokes


def template_score(scenario, demo):
    """A drawing take's ink against the template the page shows, in a line (the person
    decides on it whether to keep the take); None for another task. A take that cannot be
    scored says why ("not scored (...)"): a score never costs a take, nor a listing."""
    from hemg_drake.evaluation import template_errors

    if scenario.task != "drawing":
        return None
    template = template_strokes(scenario.task_plan())
    try:
        drawn, errors = template_errors(demo, template)
    except ValueError as error:
        return f"not scored ({error})"
    if drawn == 0:
        return "no ink"
    shapes = " / ".join("-" if e is None else f"{1e3 * e:.1f}" for e in errors)
    return (f"{drawn} ink stroke{'s' if drawn > 1 else ''} for the template's "
            f"{len(template)}, {shapes} mm off in shape")  # fmt: skip


def describe_trim(c, span, end_time):
    """One line for the terminal: what the trim of take ``c`` removed."""
    t_start, t_end = span
    return (
        f"take {c}: trimmed {t_start:.2f} s of idle lead-in and {end_time - t_end:.2f} s of "
        f"lead-out; kept {t_start:.2f}-{t_end:.2f} s ({t_end - t_start:.2f} s)"
    )


# -- hemg-drake takes -----------------------------------------------------------------------
def list_takes(run, *, scores=True):
    """One row per demonstration in ``run``'s dataset: (number, operator, seconds, samples,
    files of its own, score): checked against the manifest; the score a drawing's ink against
    the template at the take's placement (:func:`template_score`), None for another task
    (or without ``scores``)."""
    from hemg_drake.learning.demos import load_dataset
    from hemg_drake.placements import demonstration_scenario
    from hemg_drake.run_folder import RunFolder
    from hemg_drake.scenario import parse_scenario

    folder = RunFolder(run)
    folder.check("demonstrate", folder.dataset, run_hint="hemg-drake teleop or demonstrate")
    demos, metadata = load_dataset(folder.dataset)
    operators = metadata.get("operators", ["simulated"] * len(demos))
    listed = folder.manifest()["demonstrate"]["files"]
    scenario = None
    if scores and metadata.get("task") == "drawing" and "scenario" in metadata:
        scenario = parse_scenario(metadata["scenario"], source=f"{run}/dataset.npz")
    rows = []
    for c, demo in enumerate(demos, start=1):
        own = [n for n in (f"inputs_{c}.npz", f"replay_{c}.html") if n in listed]
        score = None
        if scenario is not None:
            score = template_score(demonstration_scenario(scenario, demo.seed), demo)
        rows.append((c, operators[c - 1], float(demo.time[-1] - demo.time[0]), len(demo), own,
                     score))  # fmt: skip
    return rows


def remove_take(run, number, *, progress=print):
    """Remove demonstration ``number`` (1-based) from ``run``: the dataset without it, the
    later takes' ``inputs_<c>.npz`` / ``replay_<c>.html`` renumbered, the figures redrawn,
    in one transaction. Returns the files of the new version (shown names)."""
    from hemg_drake.learning.demos import load_dataset, save_dataset
    from hemg_drake.run_folder import RunFolder
    from hemg_drake.scenario import parse_scenario
    from hemg_drake.viz.figures import plot_demonstrations, plot_emg_envelopes, save_figure

    rows = list_takes(run, scores=False)  # checks the dataset first: a bad folder changes nothing
    if not 1 <= number <= len(rows):
        raise ValueError(
            f"--remove {number}: {run} holds takes 1..{len(rows)}; give one of them"
        )
    if len(rows) == 1:
        raise ValueError(
            f"--remove {number}: it is the only demonstration in {run}; a dataset keeps at "
            "least one (remove the folder yourself if you want none)"
        )
    with RunFolder.output(run).transaction("demonstrate", keep_own=True) as folder:
        demos, metadata = load_dataset(folder.dataset)
        listed = RunFolder(run).manifest()["demonstrate"]
        own = [n for n in listed["files"] if n.startswith(("inputs_", "replay_"))]
        # The new version starts from links to every old take file; a renumbered one is a
        # new file there (a copy: a kept link must keep its name and bytes).
        moved = {}
        for name in own:
            stem, suffix = name.split(".", 1)
            kind, c = stem.rsplit("_", 1)
            c = int(c)
            os.unlink(folder / name)
            if c != number:
                moved[f"{kind}_{c - (c > number)}.{suffix}"] = name
        for new, old in moved.items():
            if new == old:
                os.link(RunFolder(run) / old, folder / new)
            else:
                shutil.copyfile(RunFolder(run) / old, folder / new)
        kept = [d for c, d in enumerate(demos, start=1) if c != number]
        automatic = ("format_version", "num_demonstrations", "seeds", "versions")
        record = {k: v for k, v in metadata.items() if k not in automatic}
        if isinstance(record.get("operators"), list) and len(record["operators"]) == len(demos):
            record["operators"] = [v for c, v in enumerate(record["operators"], 1) if c != number]
        scenario = parse_scenario(metadata["scenario"], source=f"{run}/dataset.npz")
        save_dataset(folder.dataset, kept, record)
        figures = [folder / "demonstrations.png", folder / "fig6_emg.png"]
        save_figure(plot_demonstrations(kept, task=scenario.task), figures[0])
        save_figure(plot_emg_envelopes(kept[0].emg, per_channel=scenario.emg.per_channel),
                    figures[1])  # fmt: skip
        written = [folder.dataset, *sorted(folder / n for n in moved), *figures]
        command = listed.get("command")
        folder.finish("demonstrate", written, command=command)
    progress(f"removed take {number} of {len(rows)} from {run}")
    return [folder.shown(p) for p in written]
