"""The tasks' figures: the pin's reproduction (Fig. 8 (d)-(f)), the drawing's (Fig. 10) with
its steps I-VI, the strokes (Fig. 11) and the placements seen from above."""

import numpy as np
from matplotlib.figure import Figure

from hemg_drake.viz.figures.common import STIFFNESS_LABEL, STIFFNESS_NOTE

ROMAN = ("I", "II", "III", "IV", "V", "VI")


def _demos_and_reproduction(axes, demos, log, demo_values, log_values):
    """Demonstrations in grey, the reproduction in red, on one axis."""
    for c, demo in enumerate(demos):
        axes.plot(demo.time, demo_values(demo), color="0.6", linewidth=1.0,
                  label="demonstrations" if c == 0 else None)
    axes.plot(log.time, log_values(log), color="tab:red", linewidth=1.4, label="reproduction")


def plot_pin_reproduction(demos, log):
    """Fig. 8 (d)-(f): reproduced position, velocity, tracking force and stiffness of the pin.

    Parameters
    ----------
    demos : sequence of Demonstration (grey): ``p_WE``, ``v_WE``, ``gain``.
    log : ReproductionLog (red): ``p_WE``, ``v_WE``, ``F_tr``, ``k_star`` against ``time``.

    Returns
    -------
    figure : matplotlib.figure.Figure
        ``figure.axes[:9]``, 3 x 3 row by row: position, velocity, tracking force along x, y,
        z; ``figure.axes[9]``, across the width: the stiffness k* the arm was given against
        the demonstrated gain K.
    """
    figure = Figure(figsize=(10, 9), layout="constrained")
    layout = figure.add_gridspec(4, 3)
    grid = np.empty((3, 3), dtype=object)
    for row in range(3):
        for i in range(3):
            share = grid[0, 0] if (row, i) != (0, 0) else None
            grid[row, i] = figure.add_subplot(layout[row, i], sharex=share)
    stiffness = figure.add_subplot(layout[3, :], sharex=grid[0, 0])
    for i, axis in enumerate("xyz"):
        _demos_and_reproduction(grid[0, i], demos, log, lambda d, i=i: d.p_WE[:, i],
                                lambda r, i=i: r.p_WE[:, i])
        _demos_and_reproduction(grid[1, i], demos, log, lambda d, i=i: d.v_WE[:, i],
                                lambda r, i=i: r.v_WE[:, i])
        grid[2, i].plot(log.time, log.F_tr[:, i], color="tab:red", linewidth=1.4)
        grid[0, i].set_ylabel(f"{axis} (m)")
        grid[1, i].set_ylabel(f"d{axis}/dt (m/s)")
        grid[2, i].set_ylabel(f"F_tr,{axis} (N)")
        grid[2, i].set_xlabel("time (s)")
    _demos_and_reproduction(stiffness, demos, log, lambda d: d.gain, lambda r: r.k_star)
    stiffness.set_ylabel(STIFFNESS_LABEL)
    stiffness.set_xlabel(f"time (s)          {STIFFNESS_NOTE}")
    stiffness.set_title("stiffness: reproduced k* (red) against the demonstrated gain K (grey)",
                        fontsize="medium")
    grid[0, 0].legend(loc="best", fontsize="small")
    figure.suptitle("Cotter pin: reproduced position (d), velocity (e), tracking force (f) "
                    "and stiffness")
    return figure


def steps_from_contact(time, f_WE, *, min_gap=0.25):
    """Boundaries of the drawing's steps I-VI (s), shape (7,), from a logged pen force.

    The pen-down stretches are the runs of samples whose force exceeds the ink's contact
    threshold; runs less than ``min_gap`` seconds apart are one stroke (a bounce is not a
    pen lift). Step I runs from the log's start to the end of stroke 1, II to the start of
    stroke 2, III to its end, and so on, VI to the log's end (as ``drawing_steps`` does on a
    plan).

    Returns
    -------
    array, shape (7,), or None when the log does not show exactly three strokes.
    """
    from hemg_drake.analysis.contact import in_contact

    time = np.asarray(time, dtype=float)
    down = in_contact(f_WE)
    if time.shape != down.shape:
        raise ValueError(f"time must have shape {down.shape} (one per force), got {time.shape}")
    edges = np.flatnonzero(np.diff(np.concatenate([[0], down.astype(int), [0]])))
    runs = [[time[start], time[end - 1]] for start, end in zip(edges[0::2], edges[1::2])]
    strokes = []
    for run in runs:
        if strokes and run[0] - strokes[-1][1] < min_gap:
            strokes[-1][1] = run[1]
        else:
            strokes.append(run)
    if len(strokes) != 3:
        return None
    (s1, e1), (s2, e2), (s3, e3) = strokes
    return np.array([time[0], e1, s2, e2, s3, e3, time[-1]])


def mark_steps(axes_list, steps):
    """Dashed lines at the inner boundaries of steps I-VI, their numerals above the first axis."""
    steps = np.asarray(steps, dtype=float)
    if steps.shape != (7,) or not np.all(np.diff(steps) >= 0):
        raise ValueError(f"steps must be 7 increasing times (s), got {steps!r}")
    for axes in axes_list:
        for boundary in steps[1:-1]:
            axes.axvline(boundary, color="0.3", linestyle="--", linewidth=0.8)
    top = axes_list[0]
    for numeral, (start, end) in zip(ROMAN, zip(steps[:-1], steps[1:]), strict=True):
        top.text((start + end) / 2, 1.02, numeral, transform=top.get_xaxis_transform(),
                 ha="center", va="bottom", fontsize="medium", fontweight="bold")


def plot_drawing_reproduction(demos, log, *, steps=None):
    """Fig. 10: x, y, z and stiffness of the drawing demonstrations (grey) and reproduction (red).

    Parameters
    ----------
    demos : sequence of Demonstration: ``p_WE``, ``gain``, ``f_WE`` (for the steps).
    log : ReproductionLog: ``p_WE``, ``k_star``, ``f_WE`` (for the steps).
    steps : array of 7 times (s), None or False
        The boundaries of steps I-VI (``drawing_steps(plan)``), marked on every axis. None
        (default): from the reproduction's own pen force (:func:`steps_from_contact`), else
        from the first demonstration that shows three strokes; False: no marks.

    Returns
    -------
    figure : matplotlib.figure.Figure, four axes sharing time.
    """
    demos = list(demos)
    figure = Figure(figsize=(8, 8.5), layout="constrained")
    grid = figure.subplots(4, 1, sharex=True)
    for i, axis in enumerate("xyz"):
        _demos_and_reproduction(grid[i], demos, log, lambda d, i=i: d.p_WE[:, i],
                                lambda r, i=i: r.p_WE[:, i])
        grid[i].set_ylabel(f"{axis} (m)")
    _demos_and_reproduction(grid[3], demos, log, lambda d: d.gain, lambda r: r.k_star)
    grid[3].set_ylabel(STIFFNESS_LABEL)
    grid[3].set_xlabel(f"time (s)\n{STIFFNESS_NOTE}")
    grid[0].legend(loc="best", fontsize="small")
    title = "Drawing: demonstrations and reproduction (Fig. 10)"
    if steps is None:
        logged = [r for r in [log, *demos] if getattr(r, "f_WE", None) is not None]
        steps = next((found for found in (steps_from_contact(r.time, r.f_WE) for r in logged)
                      if found is not None), None)
        if steps is None:
            title += "; steps I-VI not marked: no log shows three strokes"
    if steps is not None and steps is not False:
        mark_steps(list(grid), steps)
    figure.suptitle(title)
    return figure


def plot_strokes(strokes, *, demonstrated=(), title="Drawn strokes seen from above (Fig. 11)"):
    """Fig. 11: the ink strokes in the paper's plane (x, y of the world), equal axes.

    Parameters
    ----------
    strokes : sequence of arrays, shape (k, >= 2), m; one coloured line each.
    demonstrated : sequence of arrays, shape (k, >= 2), m; thin grey lines underneath.

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    figure = Figure(figsize=(5, 6), layout="constrained")
    axes = figure.subplots()
    lines = [(s, "0.7", 1.0, "demonstrations" if i == 0 else None)
             for i, s in enumerate(demonstrated)]
    lines += [(s, None, 2.0, f"stroke {i}") for i, s in enumerate(strokes, start=1)]
    for stroke, color, width, label in lines:
        stroke = np.asarray(stroke, dtype=float)
        if stroke.ndim != 2 or stroke.shape[1] < 2:
            raise ValueError(f"a stroke must have shape (k, 2 or 3), got {stroke.shape}")
        axes.plot(stroke[:, 0], stroke[:, 1], color=color, linewidth=width, label=label)
    axes.set_aspect("equal")
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    if lines:
        axes.legend(loc="best", fontsize="small")
    axes.set_title(title)
    return figure


def plot_placements(demos, log, *, task, X_WT=None, title=None):
    """Demonstrations at their placements (grey) and a reproduction at a new one (red), seen
    from above (world x, y).

    Each path is the tool point; for the drawing, the ink (pen on the paper) is drawn thick.
    A demonstration's scene frame (its ``frame_b``, ``frame_A``: origin and x axis) is marked
    in grey, the reproduction's (``X_WT``) in red.

    Parameters
    ----------
    demos : sequence of Demonstration, with task frames (or None: no frame marks).
    log : ReproductionLog (time, p_WE, f_WE).
    task : {"cotter_pin", "drawing"}
    X_WT : RigidTransform, optional; the reproduction's scene pose.

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    from hemg_drake.analysis.contact import in_contact, ink_strokes

    figure = Figure(figsize=(6, 6), layout="constrained")
    axes = figure.subplots()
    span = []

    def draw(time, p_WE, f_WE, color, label):
        p_WE = np.asarray(p_WE, dtype=float)
        span.append(p_WE[:, :2])
        axes.plot(p_WE[:, 0], p_WE[:, 1], color=color, linewidth=0.6, label=label)
        if task == "drawing":
            for stroke in ink_strokes(time, p_WE, in_contact(f_WE), min_points=10):
                axes.plot(stroke[:, 0], stroke[:, 1], color=color, linewidth=2.2)
        else:
            axes.plot(*p_WE[0, :2], "o", color=color, markersize=5)

    def frame(R, p, color):
        axes.plot(*p[:2], "+", color=color, markersize=10, markeredgewidth=1.5)
        axes.annotate("", xy=p[:2] + 0.03 * R[:2, 0], xytext=p[:2],
                      arrowprops=dict(arrowstyle="->", color=color, linewidth=1.2))  # fmt: skip

    for c, demo in enumerate(demos):
        draw(demo.time, demo.p_WE, demo.f_WE, "0.6", "demonstrations" if c == 0 else None)
        if demo.frames is not None:
            frame(demo.frame_A[-1], demo.frame_b[-1], "0.45")
    draw(log.time, log.p_WE, log.f_WE, "tab:red", "reproduction at a new placement")
    if X_WT is not None:
        frame(X_WT.rotation().matrix(), X_WT.translation(), "tab:red")
    points = np.concatenate(span)
    middle, half = points.mean(axis=0), 0.55 * np.ptp(points, axis=0).max() + 0.03
    axes.set_xlim(middle[0] - half, middle[0] + half)
    axes.set_ylim(middle[1] - half, middle[1] + half)
    axes.set_aspect("equal")
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.legend(loc="best", fontsize="small")
    name = task.replace("_", " ")
    axes.set_title(title or f"{name}: demonstrated placements and a new one, from above")
    return figure
