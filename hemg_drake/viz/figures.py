"""The paper's figures, as plain functions returning matplotlib Figures.

Figures are built with ``matplotlib.figure.Figure`` (no pyplot state), so they
work under any backend; ``save_figure`` writes one atomically.
"""

import io
import warnings
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from hemg_drake.control.pd import STIFFNESS_SCALE
from hemg_drake.emg.envelope import moving_rms
from hemg_drake.emg.gain import (
    A_EMG,
    DEFAULT_K_MAX,
    DEFAULT_K_MIN,
    activation,
    gain_from_activation,
)
from hemg_drake.emg.sources import MYO_RATE
from hemg_drake.fileio import write_bytes_atomic

# K is a gain: joint j of the slave's PD gets the stiffness k_j = K s_j N·m/rad, with s_j
# from ``hemg_drake.control.pd.STIFFNESS_SCALE`` (20 at the shoulder ... 0.1 at the last wrist
# roll). So K is the stiffness of a joint with s_j = 1, in N·m/rad.
STIFFNESS_UNIT = "N·m/rad per unit s_j"
STIFFNESS_LABEL = f"stiffness K\n({STIFFNESS_UNIT})"
# Below the panel, for readers who do not know s_j.
STIFFNESS_NOTE = "K sets joint j's PD stiffness to K·s_j N·m/rad, s = ({})".format(
    ", ".join(f"{s:g}" for s in STIFFNESS_SCALE))
ROMAN = ("I", "II", "III", "IV", "V", "VI")


def save_figure(figure, path, *, dpi=150):
    """Write ``figure`` to ``path`` atomically; the format follows the suffix (.png, .svg, .pdf)."""
    path = Path(path)
    buffer = io.BytesIO()
    figure.savefig(buffer, format=path.suffix.lstrip(".").lower() or "png", dpi=dpi)
    write_bytes_atomic(path, buffer.getvalue())


def plot_emg_envelopes(samples, windows=(10, 20, 30), *, rate=MYO_RATE, per_channel=False):
    """Fig. 6: the summed raw sEMG (eq. 1) and its moving-RMS envelope per window (eq. 2).

    Parameters
    ----------
    samples : array-like, shape (n_samples, 8)
        Raw sEMG (MYO units), oldest first.
    windows : sequence of int
        The L_win values to compare (paper: 10, 20, 30).
    rate : float
        Sample rate in Hz (MYO: 200).
    per_channel : bool
        Plot the per-channel envelope instead of the paper's RMS of the sum.

    Returns
    -------
    figure : matplotlib.figure.Figure
        Two axes sharing time: the summed signal, then one envelope line per
        window (labelled ``L_win = N``).
    """
    windows = list(windows)
    if not windows:
        raise ValueError("windows must list at least one window length")
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be positive, got {rate!r}")
    envelopes = [moving_rms(samples, window, per_channel=per_channel) for window in windows]
    summed = np.asarray(samples, dtype=float).sum(axis=1)
    time = np.arange(len(summed)) / rate

    figure = Figure(figsize=(8, 5), layout="constrained")
    raw_axes, envelope_axes = figure.subplots(2, 1, sharex=True)
    raw_axes.plot(time, summed, color="0.5", linewidth=0.6)
    raw_axes.set_ylabel("summed sEMG u (eq. 1)")
    for window, envelope in zip(windows, envelopes, strict=True):
        envelope_axes.plot(time, envelope, linewidth=1.2, label=f"L_win = {window}")
    envelope_axes.set_ylabel("per-channel RMS sum" if per_channel else "RMS of u (eq. 2)")
    envelope_axes.set_xlabel("time (s)")
    envelope_axes.legend(loc="upper right")
    raw_axes.set_title("sEMG and its moving-RMS envelope (Fig. 6)")
    return figure


def plot_gain_law(A_emg_values=(A_EMG,), *, k_min=DEFAULT_K_MIN, k_max=DEFAULT_K_MAX):
    """Eq. 22: activation a(u) and gain K against the normalised envelope u, per A_emg.

    Parameters
    ----------
    A_emg_values : sequence of float
        Shape factors to compare (Table I: -0.6981); each non-zero.
    k_min, k_max : float
        Gain at rest and at maximum contraction.

    Returns
    -------
    figure : matplotlib.figure.Figure
        Two axes sharing u in [0, 1]: a(u), then K(u); one line per A_emg.
    """
    A_emg_values = list(A_emg_values)
    if not A_emg_values:
        raise ValueError("A_emg_values must list at least one shape factor")
    u = np.linspace(0.0, 1.0, 101)
    figure = Figure(figsize=(8, 3.5), layout="constrained")
    activation_axes, gain_axes = figure.subplots(1, 2, sharex=True)
    for A_emg in A_emg_values:
        a = activation(u, A_emg)
        label = f"A_emg = {A_emg:g}"
        activation_axes.plot(u, a, label=label)
        gain_axes.plot(u, gain_from_activation(a, k_min=k_min, k_max=k_max), label=label)
    activation_axes.set_ylabel("activation a(u)")
    gain_axes.set_ylabel(f"gain K ({STIFFNESS_UNIT})")
    for axes in (activation_axes, gain_axes):
        axes.set_xlabel("normalised envelope u")
    activation_axes.legend(loc="lower right")
    figure.suptitle("Gain law (eq. 22): a stronger contraction gives a stiffer slave")
    return figure


def plot_time_series(time, series, *, title=None):
    """Signals against time, one axis each, sharing the time axis.

    Parameters
    ----------
    time : array-like, shape (T,)
        Seconds.
    series : dict of str to array-like, shape (T,) or (T, k)
        Axis label -> signal; a (T, k) signal with k > 1 draws k lines labelled by column
        (x, y, z when k = 3).
    title : str, optional

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    time = np.asarray(time, dtype=float)
    if time.ndim != 1:
        raise ValueError(f"time must have shape (T,), got {time.shape}")
    if not series:
        raise ValueError("series must name at least one signal")
    arrays = {}
    for label, values in series.items():
        values = np.asarray(values, dtype=float)
        if values.ndim not in (1, 2) or len(values) != len(time):
            raise ValueError(
                f"signal {label!r} must have shape ({len(time)},) or ({len(time)}, k), "
                f"got {values.shape}"
            )
        arrays[label] = values[:, 0] if values.ndim == 2 and values.shape[1] == 1 else values
    figure = Figure(figsize=(8, 1.8 * len(arrays) + 0.6), layout="constrained")
    axes_list = np.atleast_1d(figure.subplots(len(arrays), 1, sharex=True))
    for axes, (label, values) in zip(axes_list, arrays.items(), strict=True):
        if values.ndim == 1:
            axes.plot(time, values, linewidth=1.0)
        else:
            names = "xyz" if values.shape[1] == 3 else [str(i) for i in range(values.shape[1])]
            for column, name in zip(values.T, names, strict=True):
                axes.plot(time, column, linewidth=1.0, label=name)
            axes.legend(loc="upper right", fontsize="small")
        axes.set_ylabel(label)
    axes_list[-1].set_xlabel("time (s)")
    if title:
        figure.suptitle(title)
    return figure


def plot_demonstrations(demos, *, task):
    """The recorded demonstrations: Fig. 8 (a)-(b) for the cotter pin, Fig. 10 for drawing.

    Parameters
    ----------
    demos : sequence of Demonstration
        Each with ``time`` (T,), ``p_WE`` and ``v_WE`` (T, 3), ``gain`` (T,); one line each.
    task : {"cotter_pin", "drawing"}
        ``"cotter_pin"``: positions (top row) and velocities (bottom row) of the tool point
        along x, y, z (Fig. 8 (a)-(b)). ``"drawing"``: x, y, z and the stiffness K, one axis
        each (Fig. 10).

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    demos = list(demos)
    if not demos:
        raise ValueError("plot_demonstrations needs at least one demonstration")
    if task not in ("cotter_pin", "drawing"):
        raise ValueError(f"task must be 'cotter_pin' or 'drawing', got {task!r}")
    if task == "cotter_pin":
        figure = Figure(figsize=(10, 5), layout="constrained")
        grid = figure.subplots(2, 3, sharex=True)
        panels = [(grid[0, i], "p_WE", i, f"{axis} (m)") for i, axis in enumerate("xyz")]
        panels += [(grid[1, i], "v_WE", i, f"d{axis}/dt (m/s)") for i, axis in enumerate("xyz")]
        bottom = grid[1]
        title = "Demonstrations of pulling the cotter pin (Fig. 8 (a)-(b))"
    else:
        figure = Figure(figsize=(8, 7), layout="constrained")
        grid = figure.subplots(4, 1, sharex=True)
        panels = [(grid[i], "p_WE", i, f"{axis} (m)") for i, axis in enumerate("xyz")]
        panels.append((grid[3], "gain", None, STIFFNESS_LABEL))
        bottom = grid[3:]
        title = "Demonstrations of drawing (Fig. 10): position and stiffness"
    for axes, field, column, label in panels:
        for c, demo in enumerate(demos, start=1):
            values = getattr(demo, field)
            axes.plot(demo.time, values if column is None else values[:, column],
                      linewidth=1.0, label=f"demo {c}")
        axes.set_ylabel(label)
    for axes in bottom:
        axes.set_xlabel("time (s)")
    panels[0][0].legend(loc="best", fontsize="small")
    figure.suptitle(title)
    return figure


def plot_reproductions(demos, reproductions):
    """Demonstrations against reproductions per axis: Fig. 8 (d)-(e) and the stiffness.

    Parameters
    ----------
    demos : sequence of Demonstration
        Drawn in thin grey: ``p_WE``, ``v_WE`` (T, 3) and ``gain`` (T,) against ``time``.
    reproductions : dict of str to Reproduction
        Label (e.g. the weighting) -> ``reproduce(...)`` result with 3-D positions; one
        coloured line each (its stiffness only when ``k`` is not None).

    Returns
    -------
    figure : matplotlib.figure.Figure
        Rows: position, velocity (x, y, z columns), then the stiffness across the width.
    """
    demos = list(demos)
    if not demos or not reproductions:
        raise ValueError("plot_reproductions needs demonstrations and at least one reproduction")
    for label, reproduction in reproductions.items():
        if np.shape(reproduction.x)[1:] != (3,):
            raise ValueError(f"reproduction {label!r} must have 3-D positions, got "
                             f"{np.shape(reproduction.x)}")
    figure = Figure(figsize=(10, 7), layout="constrained")
    grid = figure.subplot_mosaic([["x", "y", "z"], ["vx", "vy", "vz"], ["k", "k", "k"]])
    for c, demo in enumerate(demos):
        label = "demonstrations" if c == 0 else None
        for i, axis in enumerate("xyz"):
            grid[axis].plot(demo.time, demo.p_WE[:, i], color="0.7", linewidth=0.8, label=label)
            grid[f"v{axis}"].plot(demo.time, demo.v_WE[:, i], color="0.7", linewidth=0.8)
        grid["k"].plot(demo.time, demo.gain, color="0.7", linewidth=0.8, label=label)
    for label, reproduction in reproductions.items():
        for i, axis in enumerate("xyz"):
            grid[axis].plot(reproduction.t, reproduction.x[:, i], linewidth=1.3, label=label)
            grid[f"v{axis}"].plot(reproduction.t, reproduction.xdot[:, i], linewidth=1.3)
        if reproduction.k is not None:
            grid["k"].plot(reproduction.t, reproduction.k[:, 0], linewidth=1.3, label=label)
        else:
            grid["k"].plot([], [])  # keep the colours of the rows in step
    for axis in "xyz":
        grid[axis].set_ylabel(f"{axis} (m)")
        grid[f"v{axis}"].set_ylabel(f"d{axis}/dt (m/s)")
        grid[f"v{axis}"].set_xlabel("time (s)")
    grid["k"].set_ylabel(STIFFNESS_LABEL)
    grid["k"].set_xlabel("time (s)")
    grid["x"].legend(loc="best", fontsize="small")
    figure.suptitle("Demonstrations (grey) and HSMM-GMR reproductions")
    return figure


# Up to this many states are drawn as lines with a legend (matplotlib's 10-colour cycle
# gives each its own colour); more become a heat map.
MAX_STATE_LINES = 10


def state_activations_title(task=None, along=None):
    """The title of a state-activation plot: the paper's Fig. 8 (c) only for the cotter pin.

    Parameters
    ----------
    task : {"cotter_pin", "drawing"} or None
    along : str or int, optional
        What the weights were computed on, e.g. ``"the reproduction"``; an integer c stands
        for ``"demonstration c"`` (numbered from 1).
    """
    if task not in (None, "cotter_pin", "drawing"):
        raise ValueError(f"task must be 'cotter_pin', 'drawing' or None, got {task!r}")
    if isinstance(along, bool) or (isinstance(along, int) and along < 1):
        raise ValueError(f"along must be a text or a demonstration number >= 1, got {along!r}")
    if isinstance(along, int):
        along = f"demonstration {along}"
    title = "HSMM state activations h"
    if task is not None:
        title += ", " + task.replace("_", " ")
    if along:
        title += f", on {along}"
    # The paper plots the activations for the cotter pin only (Fig. 8 (c)).
    return title + (" (Fig. 8 (c))" if task == "cotter_pin" else " (eq. 12)")


def plot_state_activations(time, h, *, title=None, task=None, along=None):
    """State weights over time: Fig. 8 (c) for the cotter pin.

    Up to ``MAX_STATE_LINES`` states are drawn as one line each with a legend; more (the
    drawing's N = 18) as a heat map, states up the side, with a colour bar for h_i, so no
    two states share a colour.

    Parameters
    ----------
    time : array-like, shape (T,)
        Seconds, increasing.
    h : array-like, shape (T, N)
        Weights in [0, 1], each row summing to 1 (``Reproduction.h``, ``forward_variable``).
    title : str, optional
        Wins over the title made from ``task`` and ``along`` by :func:`state_activations_title`.
    task, along : see :func:`state_activations_title`.

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    time, h = np.asarray(time, dtype=float), np.asarray(h, dtype=float)
    if time.ndim != 1 or h.ndim != 2 or len(h) != len(time) or len(time) == 0:
        raise ValueError(f"need time (T,) and h (T, N), got {time.shape} and {h.shape}")
    if title is None:
        title = state_activations_title(task, along)
    n_states = h.shape[1]
    if n_states <= MAX_STATE_LINES:
        figure = Figure(figsize=(8, 2.8), layout="constrained")
        axes = figure.subplots()
        for i, weights in enumerate(h.T, start=1):
            axes.plot(time, weights, linewidth=1.2, label=f"state {i}")
        axes.legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize="small")
        axes.set_ylim(-0.05, 1.05)
        axes.set_ylabel("h_i")
    else:
        figure = Figure(figsize=(8, 0.6 + 0.17 * n_states), layout="constrained")
        axes = figure.subplots()
        # Cell edges halfway between samples, so each sample's column is centred on its time.
        mid = (time[1:] + time[:-1]) / 2 if len(time) > 1 else np.array([])
        step = time[1] - time[0] if len(time) > 1 else 1.0
        edges = np.concatenate([[time[0] - step / 2], mid, [time[-1] + step / 2]])
        mesh = axes.pcolormesh(edges, np.arange(n_states + 1) + 0.5, h.T, cmap="Blues",
                               vmin=0.0, vmax=1.0, shading="flat")
        colorbar = figure.colorbar(mesh, ax=axes, pad=0.01)
        colorbar.set_label("h_i")
        axes.set_yticks(np.arange(1, n_states + 1, 1 if n_states <= 20 else 2))
        axes.tick_params(axis="y", labelsize="small")
        axes.set_ylabel("state i")
    axes.set_xlabel("time (s)")
    axes.set_title(title)
    return figure


# The GMR field is drawn within this many standard deviations of some state.
NEAR_STD = 3.0
# With equal axes, the shorter side of the field's region is at least this fraction of the
# longer one.
MIN_SIDE_RATIO = 0.3
# Longest arrow, in grid spacings (the extrapolated field far from the data is clipped).
MAX_ARROW = 1.2


def plot_gmr_field(model, demos=(), *, plane=(0, 2), grid=15, equal_aspect=True):
    """The GMR velocity field of a fitted HSMM on a plane of positions (eqs. 14-17).

    At each grid point x the arrow is xdot*(x) = sum_i h_i(x) [mu_i^xdot + S_i^{xdot x}
    (S_i^xx)^-1 (x - mu_i^x)] with the spatial weights h_i of eq. 14; the position
    coordinates off the plane are held at the data's mean. Each state's position Gaussian
    is drawn as its one-standard-deviation ellipse, with the demonstrations' paths.

    The two axes share one scale (``equal_aspect``), so a pull that moves 2.5 mm sideways
    over 24 cm looks like the straight line it is; the region is then the data's box with
    its shorter side widened to at least ``MIN_SIDE_RATIO`` of the longer, and the figure
    takes its shape. Arrows are drawn only within ``NEAR_STD`` standard deviations of some state (in
    the plane), where the model has data: far from every state GMR only extrapolates the
    nearest state's linear term. They share one scale: the fastest is 0.9 grid spacings long,
    and a key gives a round speed.

    Parameters
    ----------
    model : HSMM
        Fitted, with 3-D positions.
    demos : sequence of Demonstration
        Paths ``p_WE`` drawn over the field.
    plane : (int, int)
        The two position coordinates spanning the plane (0 x, 1 y, 2 z).
    grid : int
        Arrows per side, >= 2.
    equal_aspect : bool
        One length scale on both axes (default); False fits each axis to the data alone,
        which magnifies a small spread along one of them.

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    from matplotlib.patches import Ellipse

    from hemg_drake.learning.reproduce import HsmmGmrPolicy

    with warnings.catch_warnings():  # drawing the field is not a reproduction: no advice
        warnings.simplefilter("ignore", UserWarning)
        policy = HsmmGmrPolicy(model, weighting="spatial")
    if policy.n_position != 3:
        raise ValueError(f"plot_gmr_field needs a model of 3-D positions, got {policy.n_position}")
    a, b = plane
    if a == b or not {a, b} <= {0, 1, 2}:
        raise ValueError(f"plane must name two different coordinates among 0, 1, 2, got {plane!r}")
    if isinstance(grid, bool) or not isinstance(grid, int) or grid < 2:
        raise ValueError(f"grid must be an integer >= 2, got {grid!r}")
    position = model.position_dims_
    means = model.means_[:, position]
    covariances = model.covariances_[:, position][:, :, position]
    centre = model.occupancy_ @ means
    # The plotted region: the states' 2-sigma boxes and the demonstrations' paths.
    spread = 2 * np.sqrt(np.diagonal(covariances, axis1=1, axis2=2))
    points = [means - spread, means + spread] + [demo.p_WE for demo in demos]
    low = np.min([p.min(axis=0) for p in points], axis=0)[[a, b]]
    high = np.max([p.max(axis=0) for p in points], axis=0)[[a, b]]
    half = 0.55 * np.maximum(high - low, 1e-6)  # 5 % margin each side
    middle = (low + high) / 2
    if equal_aspect:
        # Square cells, ``grid`` arrows along the longer side; the shorter side is widened to
        # at least MIN_SIDE_RATIO of the longer, so a thin path still has room around it.
        long_side = int(np.argmax(half))
        half[1 - long_side] = max(half[1 - long_side], MIN_SIDE_RATIO * half[long_side])
        spacing = 2 * half[long_side] / (grid - 1)
        counts = [grid, grid]
        short = max(2, int(np.ceil(2 * half[1 - long_side] / spacing - 1e-9)) + 1)
        counts[1 - long_side] = short + 1 - short % 2  # odd: a middle column through the data
        half[1 - long_side] = (counts[1 - long_side] - 1) * spacing / 2
    else:
        counts = [grid, grid]
    u = np.linspace(middle[0] - half[0], middle[0] + half[0], counts[0])
    v = np.linspace(middle[1] - half[1], middle[1] + half[1], counts[1])
    U, V = np.meshgrid(u, v)
    queries = np.tile(centre, (U.size, 1))
    queries[:, a], queries[:, b] = U.ravel(), V.ravel()
    velocity = policy.gmr.predict(queries)[0][:, : policy.n_position]

    # Far from every state the field is GMR's extrapolation (the nearest state's linear
    # term grows without bound): no arrows there, and the arrows' length scale comes from
    # the field at the states' means, where the model has data.
    offsets = np.column_stack([U.ravel(), V.ravel()])[:, None, :] - means[None][:, :, [a, b]]
    inverse = np.linalg.inv(covariances[:, [a, b]][:, :, [a, b]])
    distance2 = np.einsum("qni,nij,qnj->qn", offsets, inverse, offsets).min(axis=1)
    near = distance2 <= NEAR_STD**2
    at_means = policy.gmr.predict(means)[0][:, [a, b]]
    typical = float(np.max(np.hypot(*at_means.T))) if np.isfinite(at_means).all() else 0.0
    spacing = min(u[1] - u[0], v[1] - v[0])
    scale = typical / (0.9 * spacing) if typical > 0 else None
    planar = velocity[:, [a, b]]
    if scale is not None:  # an arrow is at most MAX_ARROW grid spacings long
        speed = np.hypot(*planar.T)
        longest = MAX_ARROW * spacing * scale
        planar = planar * np.minimum(1.0, longest / np.maximum(speed, 1e-300))[:, None]

    labels = "xyz"
    if equal_aspect:  # the figure takes the region's shape
        ratio = half[1] / half[0]
        size = (6.5, 1.6 + 5.0 * ratio) if ratio <= 1 else (2.0 + 6.0 / ratio, 7.5)
    else:
        size = (6.5, 6.3)
    figure = Figure(figsize=(max(size[0], 5.5), size[1]), layout="constrained")
    axes = figure.subplots()
    style = dict(angles="xy", scale_units="xy", scale=scale)
    axes.quiver(U.ravel()[near], V.ravel()[near], *planar[near].T, color="tab:blue",
                alpha=0.8, label="GMR velocity xdot*(x)", **style)
    for demo in demos:
        axes.plot(demo.p_WE[:, a], demo.p_WE[:, b], color="0.4", linewidth=0.8)
    for i, (mean, covariance) in enumerate(zip(means, covariances, strict=True), start=1):
        values, vectors = np.linalg.eigh(covariance[np.ix_([a, b], [a, b])])
        angle = np.degrees(np.arctan2(vectors[1, -1], vectors[0, -1]))
        width, height = 2 * np.sqrt(np.maximum(values[::-1], 0.0))
        axes.add_patch(Ellipse((mean[a], mean[b]), width, height, angle=angle, fill=False,
                               color="tab:red", linewidth=1.2))
        axes.annotate(str(i), (mean[a], mean[b]), color="tab:red", ha="center", va="center",
                      xytext=(6, 0), textcoords="offset points")
    step = 0.5 * spacing  # the outer arrows' tails sit on the region's edge
    axes.set_xlim(u[0] - step, u[-1] + step)
    axes.set_ylim(v[0] - step, v[-1] + step)
    if equal_aspect:
        axes.set_aspect("equal", adjustable="box")
    arrow_scale = f"\narrows: one grid spacing = {spacing * scale:.3g} m/s" if scale else ""
    axes.set_xlabel(f"{labels[a]} (m){arrow_scale}")
    axes.set_ylabel(f"{labels[b]} (m)")
    axes.set_title(f"GMR velocity field xdot*(x) within {NEAR_STD:g} std of a state (blue),\n"
                   "states (red, 1 std), demonstrations (grey)", loc="left", fontsize="medium")
    return figure


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
