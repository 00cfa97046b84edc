"""The learning figures: demonstrations against reproductions, the HSMM's state
activations (Fig. 8 (c)) and its GMR velocity field."""

import warnings

import numpy as np
from matplotlib.figure import Figure

from hemg_drake.viz.figures.common import STIFFNESS_LABEL


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
