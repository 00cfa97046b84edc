"""A sweep's results: the table (``results.csv``, ``results.parquet``), the figure
(``results.png``), the summary lines, and which trials a resumed sweep may skip."""

import csv
import io
import itertools
import json
import math
from pathlib import Path

import yaml

from hemg_drake.fileio import write_bytes_atomic, write_text_atomic
from hemg_drake.sweep.spec import axis_points
from hemg_drake.sweep.trial import TRIAL_FILE


def finished_record(out, trial):
    """The trial's record if it finished (status done) in ``out``, else None."""
    path = Path(out) / "trials" / trial.id / TRIAL_FILE
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    return record if record.get("status") == "done" else None


def table_rows(records, spec):
    """One row per trial: trial, status, seed, the axes' labels, error, metrics (the same
    bytes however the sweep ran: a trial's elapsed time is in its ``trial.json`` only)."""
    rows = []
    for record in records:
        row = {"trial": record["id"], "status": record["status"], "seed": record["seed"]}
        for axis in spec.axes:
            row[axis.name] = record["labels"].get(axis.name, "")
        row["error"] = record.get("error", "")
        for name in spec.metrics:
            row[name] = record["metrics"].get(name, "")
        rows.append(row)
    return rows


def write_results(records, spec, out):
    """``results.csv`` (and ``results.parquet`` with pyarrow) and ``results.png``."""
    out = Path(out)
    rows = table_rows(records, spec)
    columns = list(rows[0]) if rows else ["trial", "status"]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(out / "results.csv", buffer.getvalue())
    written = [out / "results.csv"]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        pass
    else:
        table = pa.table({name: _column([row[name] for row in rows]) for name in columns})
        sink = io.BytesIO()
        pq.write_table(table, sink)
        write_bytes_atomic(out / "results.parquet", sink.getvalue())
        written.append(out / "results.parquet")
    if spec.axes and spec.metrics and any(r["status"] == "done" for r in records):
        written.append(plot_results(records, spec, out / "results.png"))
    return written


def _column(values):
    """A Parquet column: missing cells (None, "") null; numbers, or else text throughout
    (a failed trial's empty metric beside the others' floats stays a float column)."""
    values = [None if v is None or v == "" else v for v in values]
    present = [v for v in values if v is not None]
    if all(isinstance(v, bool) for v in present) or all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in present
    ):
        return values
    if all(isinstance(v, (int, float)) for v in present):
        return [None if v is None else float(v) for v in values]
    return [None if v is None else str(v) for v in values]


def _number(value):
    if isinstance(value, bool):
        return float(value)
    if isinstance(value, (int, float)):
        return float(value)
    return math.nan


def _as_float(label):
    try:
        return float(yaml.safe_load(str(label)))
    except (TypeError, ValueError, yaml.YAMLError):
        return None


def plot_results(records, spec, path, *, title=None):
    """Per metric (rows) and varied axis (columns): the metric's mean over seeds against the
    axis' values, one line per case of the other axes (grid) and +-1 standard deviation
    shaded. Booleans are shown as rates (the mean of 0/1)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from hemg_drake.viz.figures import save_figure

    done = [r for r in records if r["status"] == "done"]
    metrics_ = list(spec.metrics)
    axes_ = list(spec.axes)
    figure, grid = plt.subplots(len(metrics_), len(axes_), squeeze=False,
                                figsize=(4.2 * len(axes_), 2.6 * len(metrics_)))  # fmt: skip
    for column, axis in enumerate(axes_):
        labels = [label for label, _ in axis_points(axis)]
        numeric = [_as_float(label) for label in labels]
        numeric_x = all(v is not None for v in numeric)
        x = np.array(numeric if numeric_x else range(len(labels)), dtype=float)
        others = [a for a in axes_ if a is not axis] if spec.design == "grid" else []
        present = {tuple(r["labels"].get(a.name, "") for a in others) for r in done}
        # The other axes' cases in the sweep file's order.
        ordered = itertools.product(*[[label for label, _ in axis_points(a)] for a in others])
        groups = [group for group in ordered if group in present]
        others = [a.name for a in others]
        for row, metric in enumerate(metrics_):
            ax = grid[row][column]
            for group in groups:
                mean, spread = [], []
                for label in labels:
                    values = [
                        _number(r["metrics"].get(metric)) for r in done
                        if r["labels"].get(axis.name) == label
                        and tuple(r["labels"].get(n, "") for n in others) == group
                    ]  # fmt: skip
                    values = [v for v in values if math.isfinite(v)]
                    mean.append(np.mean(values) if values else np.nan)
                    spread.append(np.std(values) if values else np.nan)
                mean, spread = np.array(mean), np.array(spread)
                name = ", ".join(f"{n}={g}" for n, g in zip(others, group, strict=True))
                (line,) = ax.plot(x, mean, "o-", label=name or None, markersize=3)
                ax.fill_between(x, mean - spread, mean + spread, alpha=0.2, color=line.get_color())
            if not numeric_x:
                ax.set_xticks(x, labels)
            if row == len(metrics_) - 1:
                ax.set_xlabel(axis.name)
            if column == 0:
                ax.set_ylabel(metric.replace(".", ".\n", 1), fontsize=8)
            ax.grid(alpha=0.3)
            if row == 0 and groups and groups[0]:
                ax.legend(fontsize=7)
    seeds = len(spec.seeds)
    figure.suptitle(title or f"{len(done)} trials, mean and +-1 std over {seeds} seed(s)",
                    fontsize=10)  # fmt: skip
    figure.tight_layout(rect=(0, 0, 1, 1 - 0.25 / figure.get_figheight()))
    save_figure(figure, path)
    plt.close(figure)
    return path


def summary(records, spec):
    """Lines of text: the mean over seeds of each metric per setting."""
    import numpy as np

    lines, groups = [], {}
    for record in records:
        key = tuple(record["labels"].get(a.name, "") for a in spec.axes)
        groups.setdefault(key, []).append(record)
    header = [a.name for a in spec.axes] + ["done"] + list(spec.metrics)
    lines.append("  ".join(header))
    for key, group in groups.items():
        done = [r for r in group if r["status"] == "done"]
        cells = [str(k) if k != "" else "-" for k in key] + [f"{len(done)}/{len(group)}"]
        for metric in spec.metrics:
            values = [_number(r["metrics"].get(metric)) for r in done]
            values = [v for v in values if math.isfinite(v)]
            cells.append(f"{np.mean(values):.4g}" if values else "-")
        lines.append("  ".join(cells))
    return lines
