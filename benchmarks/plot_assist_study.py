"""The shared-control study's figure and paired differences (docs/studies.md, "Shared
control"): per task, each measure against the one-way delay for the four assist modes, and
the emg mode's paired differences to none and to fixed (the same operator seed and style),
mean and 95 % confidence interval (Student's t over the pairs).

    python benchmarks/plot_assist_study.py runs/study_assist_pin runs/study_assist_drawing \
        -o docs/img/study_assist.png

Reads the sweeps' ``trials/*/trial.json`` (also while they run); prints the paired
differences as Markdown tables.
"""

import argparse
import json
from pathlib import Path

import numpy as np

MODES = ("none", "fixed", "confidence", "emg")
MEASURES = {
    "success": "task success (fraction)",
    "demonstration.completion_s": "pin out after (s)",
    "demonstration.muscle_effort": "muscle activation (mean)",
    "demonstration.contact_force_peak_n": "peak contact force (N)",
    "demonstration.tracking_error_m": "slave - master error (m)",
}
SUCCESS = {"cotter_pin": "demonstration.pin_out", "drawing": "demonstration.three_strokes"}


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


def delays(rows):
    return sorted({int(row["delay_ms"]) for row in rows})


def table(task, rows):
    """Markdown: per delay and measure, emg - none and emg - fixed."""
    lines = [f"**{task}** (emg minus the baseline, mean [95 % CI], n pairs)", "",
             "| delay (ms) | measure | emg - none | emg - fixed |", "|---|---|---|---|"]  # fmt: skip
    for delay in delays(rows):
        for measure, name in MEASURES.items():
            cells = []
            for baseline in ("none", "fixed"):
                mean, half, n = interval(paired(rows, measure, "emg", baseline, delay))
                cells.append("-" if n == 0 else f"{mean:+.3g} [{mean - half:+.3g}, {mean + half:+.3g}] ({n})")
            if cells != ["-", "-"]:
                lines.append(f"| {delay} | {name} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines)


def plot(studies, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    measures = list(MEASURES)
    figure, axes = plt.subplots(len(studies), len(measures), figsize=(3.2 * len(measures), 2.8 * len(studies)), squeeze=False)  # fmt: skip
    for r, (task, rows) in enumerate(studies):
        for c, measure in enumerate(measures):
            ax = axes[r, c]
            for mode in MODES:
                xs, ys = [], []
                for delay in delays(rows):
                    values = [float(row[measure]) for row in rows
                              if row["mode"] == mode and int(row["delay_ms"]) == delay
                              and row.get(measure) is not None and np.isfinite(row[measure])]  # fmt: skip
                    if values:
                        xs.append(delay)
                        ys.append(np.mean(values))
                ax.plot(xs, ys, marker="o", label=mode)
            ax.set_title(f"{task}: {MEASURES[measure]}", fontsize=8)
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
    studies = [trials(folder) for folder in args.folders]
    studies = [(task, rows) for task, rows in studies if rows]
    for task, rows in studies:
        print(table(task, rows))
        print()
    plot(studies, args.out)


if __name__ == "__main__":
    main()
