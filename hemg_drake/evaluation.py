"""What a reproduction achieved, as one JSON-ready record: Table II, the task, forces, stiffness.

Reads the demonstrations and the reproduction's log once, and computes from them (the
maths is in :mod:`hemg_drake.tasks.metrics`):

- **Table II.** Position and velocity RMSE against the mean demonstration; see
  :func:`task_metrics` for the alignments reported and the demonstrations' own floor.
- **Task success**, checked on the physics: the pin out without excessive force or
  overshoot; three strokes in shape with a bounded pen force (``SUCCESS_LIMITS``, written
  into every record).
- **Forces** (eq. 23's tracking force) and the **stiffness** (on and off the paper, and its
  correlation with the demonstrated gain).
"""

import numpy as np

from hemg_drake.learning.demos import observations
from hemg_drake.tasks import metrics
from hemg_drake.viz.ink import in_contact, ink_strokes

# Drawing: shortest pen contact (log samples, 0.01 s each) that counts as a stroke.
MIN_STROKE_SAMPLES = 10


def strokes(time, p_WE, f_WE):
    """The ink strokes of a logged run (list of (n, 3) arrays, m)."""
    return ink_strokes(time, p_WE, in_contact(f_WE), min_points=MIN_STROKE_SAMPLES)


def task_metrics(task, demos, result):
    """Table II, task success, tracking force and stiffness of one reproduction.

    Parameters
    ----------
    task : {"cotter_pin", "drawing"}
    demos : list of Demonstration
    result : ReproductionResult

    Returns
    -------
    dict (JSON-ready): ``alignment`` (the method), ``position_rmse_m``,
    ``velocity_rmse_m_per_s``, ``time_normalised`` (the same RMSEs, other alignment),
    ``stiffness_correlation``, ``tracking_force_peak_n``, ``tracking_force_mean_n``,
    ``success``, and the task's own entries.
    """
    log = result.log
    data = observations(demos)
    reproduced = log.observations()
    mean = metrics.mean_demonstration(data)
    aligned = metrics.aligned_rmse(reproduced, mean)
    plain = metrics.time_normalised_rmse(reproduced, data)
    force = metrics.force_statistics(log.F_tr)
    record = {
        "alignment": metrics.ALIGNMENT,
        "position_rmse_m": aligned["position_rmse"],
        "velocity_rmse_m_per_s": aligned["velocity_rmse"],
        "time_normalised": {
            "position_rmse_m": plain["position_rmse"],
            "velocity_rmse_m_per_s": plain["velocity_rmse"],
        },
        "stiffness_correlation": metrics.stiffness_correlation(
            reproduced[:, 6], mean[:, 6], aligned["path"]
        ),
        "tracking_force_peak_n": force["peak"],
        "tracking_force_mean_n": force["mean"],
    }
    if task == "cotter_pin":
        record.update(
            success=bool(result.pin_out),
            pin_displacement_m=result.pin_displacement,
        )
    else:
        record.update(_drawing_metrics(demos, log))
    return record


def _drawing_metrics(demos, log):
    """Strokes, their shape and placement errors (seen from above), stiffness on and off paper."""
    drawn = strokes(log.time, log.p_WE, log.f_WE)
    demo_strokes = [strokes(d.time, d.p_WE, d.f_WE) for d in demos]
    shape, placement = [], []
    for k, stroke in enumerate(drawn):
        same = [s[k][:, :2] for s in demo_strokes if len(s) > k]
        errors = metrics.stroke_errors(stroke[:, :2], same) if same else None
        shape.append(errors and errors["shape"])
        placement.append(errors and errors["placement"])
    touching = in_contact(log.f_WE)
    on_paper = float(log.k_star[touching].mean()) if touching.any() else None
    in_air = float(log.k_star[~touching].mean()) if (~touching).any() else None
    return {
        "strokes": len(drawn),
        "demonstrated_strokes": [len(s) for s in demo_strokes],
        "stroke_shape_error_m": shape,
        "stroke_placement_error_m": placement,
        "success": len(drawn) == 3,
        "stiffness_on_paper": on_paper,
        "stiffness_in_air": in_air,
    }


def format_metrics(results):
    """A plain-text table of metrics per run (run name -> metrics dict)."""
    rows = [("run", "pos RMSE (mm)", "vel RMSE (m/s)", "success", "F_tr peak/mean (N)", "k corr")]
    for name, m in results.items():
        correlation = m["stiffness_correlation"]
        rows.append((
            name,
            f"{1e3 * m['position_rmse_m']:.2f}",
            f"{m['velocity_rmse_m_per_s']:.4f}",
            str(m["success"]),
            f"{m['tracking_force_peak_n']:.2f} / {m['tracking_force_mean_n']:.2f}",
            "-" if correlation is None else f"{correlation:.2f}",
        ))  # fmt: skip
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    lines.append("RMSE alignment: DTW against the mean demonstration (docs/reproduction.md)")
    return "\n".join(lines)
