"""The shared-control study's figure and paired differences (docs/studies.md, "Shared
control"): per task, each measure against the one-way delay for the four assist modes, and
the emg mode's paired differences to none and to fixed (the same operator seed and style),
mean and 95 % confidence interval (Student's t over the pairs).

    python benchmarks/plot_assist_study.py runs/study_assist_pin runs/study_assist_drawing \
        -o docs/img/study_assist.png

Reads the sweeps' ``trials/*/trial.json`` (also while they run); one study per task and
simulated operator (the ``operator`` axis); prints the means and paired differences as
Markdown tables.
"""

import argparse
import json
from pathlib import Path

import numpy as np

MODES = ("none", "fixed", "confidence", "emg")
MEASURES = {
    "success": "task success (fraction)",
    "completed": "pin out, operator did not give up",
    "demonstration.completion_s": "pin out after (s)",
    "demonstration.strokes": "ink pieces (mean)",
    "demonstration.hand_impulse_n_s": "hand force integral (N s)",
    "demonstration.hand_work_j": "hand work on the master (J)",
    "demonstration.muscle_effort": "muscle activation (mean)",
    "demonstration.contact_force_peak_n": "peak contact force (N)",
    "demonstration.gave_up": "operator gave up (fraction)",
    "demonstration.disagreement_m": "operator - policy (m)",
    "demonstration.phase_lag_s": "phase right, lag (s)",
    "demonstration.passivity_energy_min_j": "observer energy, least (J)",
}
# The figure's panels (the tables have every measure).
FIGURE = ("success", "completed", "demonstration.hand_impulse_n_s",
          "demonstration.contact_force_peak_n", "demonstration.gave_up",
          "demonstration.disagreement_m", "demonstration.phase_lag_s",
          "demonstration.passivity_energy_min_j")  # fmt: skip
SUCCESS = {"cotter_pin": "demonstration.pin_out", "drawing": "demonstration.three_strokes"}
# The drawing's words for the measures MEASURES names after the pin.
DRAWING = {"completed": "three strokes, operator did not give up",
           "demonstration.completion_s": "third stroke done after (s)"}  # fmt: skip


def label(study, measure):
    """``measure``'s name in the tables of ``study`` ("drawing, noisy": the drawing's)."""
    if study.split(",")[0] == "drawing":
        return DRAWING.get(measure, MEASURES[measure])
    return MEASURES[measure]


def trials(folder):
    """(task, rows): the finished trials of a sweep folder, one dict per trial."""
    rows, task = [], None
    for path in sorted(Path(folder).glob("trials/*/trial.json")):
        record = json.loads(path.read_text(encoding="utf-8"))
        if record["status"] != "done":
            continue
        metrics = record["metrics"]
        task = "cotter_pin" if "demonstration.pin_out" in metrics else "drawing"
        row = {**record["labels"], "seed": record["seed"], **metrics}
        row["success"] = metrics[SUCCESS[task]]
        if "demonstration.gave_up" in metrics:  # the visual operator: it finished its plan
            row["completed"] = float(row["success"] and not metrics["demonstration.gave_up"])
        rows.append(row)
    return task, rows


def paired(rows, measure, mode, baseline, delay):
    """Differences mode - baseline over the (operator, seed) pairs at ``delay``."""
    by_key = {}
    for row in rows:
        if str(row["delay_ms"]) == str(delay):
            by_key.setdefault((row.get("operator", ""), row["seed"]), {})[row["mode"]] = row
    diffs = []
    for cell in by_key.values():
        if mode in cell and baseline in cell:
            a, b = cell[mode].get(measure), cell[baseline].get(measure)
            if a is not None and b is not None and np.isfinite(a) and np.isfinite(b):
                diffs.append(float(a) - float(b))
    return np.array(diffs)


def interval(diffs):
    """(mean, half-width of the 95 % t interval, n); NaN half-width below 2 pairs."""
    from scipy.stats import t

    n = len(diffs)
    if n == 0:
        return float("nan"), float("nan"), 0
    if n < 2 or np.all(diffs == diffs[0]):
        return float(diffs.mean()), 0.0 if n > 1 else float("nan"), n
    half = t.ppf(0.975, n - 1) * diffs.std(ddof=1) / np.sqrt(n)
    return float(diffs.mean()), float(half), n


def values(rows, measure, mode, delay):
    """The finite values of ``measure`` over the trials of one mode and delay."""
    return [float(r[measure]) for r in rows
            if r["mode"] == mode and int(r["delay_ms"]) == delay
            and r.get(measure) is not None and np.isfinite(float(r[measure]))]  # fmt: skip


def delays(rows):
    return sorted({int(row["delay_ms"]) for row in rows})


def means(task, rows):
    """Markdown: per delay and mode, each measure's mean (n trials)."""
    present = [m for m in MEASURES if any(row.get(m) is not None for row in rows)]
    lines = [f"**{task}** (mean over the trials; n per cell in the first column)", "",
             "| delay (ms) | mode | n | " + " | ".join(label(task, m) for m in present) + " |",
             "|---" * (3 + len(present)) + "|"]  # fmt: skip
    for delay in delays(rows):
        for mode in MODES:
            cell = [row for row in rows if row["mode"] == mode and int(row["delay_ms"]) == delay]
            if not cell:
                continue
            shown = []
            for measure in present:
                found = values(cell, measure, mode, delay)
                shown.append(f"{np.mean(found):.3g}" if found else "-")
            lines.append(f"| {delay} | {mode} | {len(cell)} | " + " | ".join(shown) + " |")
    return "\n".join(lines)


# The summary's columns: what decides the goal.
SUMMARY = ("completed", "success", "demonstration.contact_force_peak_n",
           "demonstration.hand_impulse_n_s")  # fmt: skip


def summary(studies):
    """Markdown: one row per study and delay; per measure the means of the modes, in the
    order none / fixed / confidence / emg."""
    first = studies[0][0] if studies else ""
    lines = ["| study | delay (ms) | n | " + " | ".join(label(first, m) for m in SUMMARY) + " |",
             "|---" * (3 + len(SUMMARY)) + "|"]  # fmt: skip
    for name, rows in studies:
        for delay in delays(rows):
            cells, counts = [], set()
            for measure in SUMMARY:
                means = []
                for mode in MODES:
                    found = values(rows, measure, mode, delay)
                    means.append(f"{np.mean(found):.2g}" if found else "-")
                    if measure == "success" and found:
                        counts.add(len(found))
                cells.append(" / ".join(means))
            n = "/".join(str(c) for c in sorted(counts))
            lines.append(f"| {name} | {delay} | {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def table(task, rows):
    """Markdown: per delay and measure, emg - none and emg - fixed."""
    lines = [f"**{task}** (emg minus the baseline, mean [95 % CI], n pairs)", "",
             "| delay (ms) | measure | emg - none | emg - fixed |", "|---|---|---|---|"]  # fmt: skip
    for delay in delays(rows):
        for measure in MEASURES:
            name, cells = label(task, measure), []
            for baseline in ("none", "fixed"):
                diffs = paired(rows, measure, "emg", baseline, delay)
                mean, half, n = interval(diffs)
                cells.append("-" if n == 0 else f"{mean:+.3g} [{mean - half:+.3g}, {mean + half:+.3g}] ({n})")
            if cells != ["-", "-"]:
                lines.append(f"| {delay} | {name} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines)


def plot(studies, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    measures = [m for m in FIGURE if any(row.get(m) is not None for _, rows in studies for row in rows)]
    columns = 4
    per_task = -(-len(measures) // columns)
    figure, axes = plt.subplots(len(studies) * per_task, columns, figsize=(3.4 * columns, 2.6 * per_task * len(studies)), squeeze=False)  # fmt: skip
    for ax in axes.flat:
        ax.set_visible(False)
    for r, (task, rows) in enumerate(studies):
        for c, measure in enumerate(measures):
            ax = axes[r * per_task + c // columns, c % columns]
            ax.set_visible(True)
            for mode in MODES:
                xs, ys, errors = [], [], []
                for delay in delays(rows):
                    found = values(rows, measure, mode, delay)
                    if found:
                        xs.append(delay)
                        ys.append(np.mean(found))
                        spread = np.array(found) - np.mean(found)
                        errors.append(interval(spread)[1] if len(found) > 1 else 0.0)
                if xs:  # the mean and its 95 % t interval, the modes side by side
                    shift = 6.0 * (MODES.index(mode) - 1.5)
                    ax.errorbar(np.array(xs) + shift, ys, yerr=np.nan_to_num(errors),
                                marker="o", ms=3, capsize=2, label=mode,
                                color=f"C{MODES.index(mode)}")  # one colour per mode, every panel  # fmt: skip
            ax.set_title(f"{task}: {label(task, measure)}", fontsize=8)
            ax.set_xlabel("one-way delay (ms)", fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=110)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+")
    parser.add_argument("-o", "--out", default="study_assist.png")
    args = parser.parse_args()
    merged = {}  # one study per task and operator, its folders' trials together
    for folder in args.folders:
        task, rows = trials(folder)
        for row in rows:
            operator = row.get("operator")
            merged.setdefault(task if operator is None else f"{task}, {operator}", []).append(row)
    operators = {"nominal": 0, "noisy": 1, "slow": 2}  # the order
    studies = sorted(merged.items(), key=lambda kv: (
        kv[0].split(", ")[0], operators.get(kv[0].split(", ")[-1], len(operators)), kv[0]))
    print(summary(studies))
    print()
    for task, rows in studies:
        print(means(task, rows))
        print()
        print(table(task, rows))
        print()
    plot(studies, args.out)


if __name__ == "__main__":
    main()
