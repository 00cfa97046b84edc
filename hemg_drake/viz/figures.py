"""The paper's figures, as plain functions returning matplotlib Figures.

Figures are built with ``matplotlib.figure.Figure`` (no pyplot state), so they
work under any backend; ``save_figure`` writes one atomically.
"""

import io
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

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
    gain_axes.set_ylabel("gain K")
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
        panels.append((grid[3], "gain", None, "stiffness K"))
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
    grid["k"].set_ylabel("stiffness K")
    grid["k"].set_xlabel("time (s)")
    grid["x"].legend(loc="best", fontsize="small")
    figure.suptitle("Demonstrations (grey) and HSMM-GMR reproductions")
    return figure


def plot_state_activations(time, h, *, title="HSMM state activations h (eq. 12)"):
    """State weights over time, one line per state: Fig. 8 (c).

    Parameters
    ----------
    time : array-like, shape (T,)
        Seconds.
    h : array-like, shape (T, N)
        Weights in [0, 1], each row summing to 1 (``Reproduction.h``, ``forward_variable``).

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    time, h = np.asarray(time, dtype=float), np.asarray(h, dtype=float)
    if time.ndim != 1 or h.ndim != 2 or len(h) != len(time):
        raise ValueError(f"need time (T,) and h (T, N), got {time.shape} and {h.shape}")
    figure = Figure(figsize=(8, 2.8), layout="constrained")
    axes = figure.subplots()
    for i, weights in enumerate(h.T, start=1):
        axes.plot(time, weights, linewidth=1.2, label=f"state {i}")
    if h.shape[1] <= 10:
        axes.legend(loc="center right", fontsize="small")
    axes.set_ylim(-0.05, 1.05)
    axes.set_xlabel("time (s)")
    axes.set_ylabel("h_i")
    axes.set_title(title)
    return figure


def plot_gmr_field(model, demos=(), *, plane=(0, 2), grid=15):
    """The GMR velocity field of a fitted HSMM on a plane of positions (eqs. 14-17).

    At each grid point x the arrow is xdot*(x) = sum_i h_i(x) [mu_i^xdot + S_i^{xdot x}
    (S_i^xx)^-1 (x - mu_i^x)] with the spatial weights h_i of eq. 14; the position
    coordinates off the plane are held at the data's mean. Each state's position Gaussian
    is drawn as its one-standard-deviation ellipse, with the demonstrations' paths.

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

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    from matplotlib.patches import Ellipse

    from hemg_drake.learning.reproduce import HsmmGmrPolicy

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
    low = np.min([p.min(axis=0) for p in points], axis=0)
    high = np.max([p.max(axis=0) for p in points], axis=0)
    margin = 0.05 * np.maximum(high - low, 1e-6)
    u = np.linspace(low[a] - margin[a], high[a] + margin[a], grid)
    v = np.linspace(low[b] - margin[b], high[b] + margin[b], grid)
    U, V = np.meshgrid(u, v)
    queries = np.tile(centre, (U.size, 1))
    queries[:, a], queries[:, b] = U.ravel(), V.ravel()
    velocity = policy.gmr.predict(queries)[0][:, : policy.n_position]

    labels = "xyz"
    figure = Figure(figsize=(6.5, 5.5), layout="constrained")
    axes = figure.subplots()
    axes.quiver(U.ravel(), V.ravel(), velocity[:, a], velocity[:, b], color="tab:blue",
                alpha=0.7, label="GMR velocity xdot*(x)")
    for demo in demos:
        axes.plot(demo.p_WE[:, a], demo.p_WE[:, b], color="0.4", linewidth=0.8)
    for i, (mean, covariance) in enumerate(zip(means, covariances, strict=True), start=1):
        values, vectors = np.linalg.eigh(covariance[np.ix_([a, b], [a, b])])
        angle = np.degrees(np.arctan2(vectors[1, -1], vectors[0, -1]))
        width, height = 2 * np.sqrt(np.maximum(values[::-1], 0.0))
        axes.add_patch(Ellipse((mean[a], mean[b]), width, height, angle=angle, fill=False,
                               color="tab:red", linewidth=1.2))
        axes.annotate(str(i), (mean[a], mean[b]), color="tab:red", ha="center", va="center")
    axes.set_xlabel(f"{labels[a]} (m)")
    axes.set_ylabel(f"{labels[b]} (m)")
    axes.set_title("GMR field (arrows), states (red, 1 std), demonstrations (grey)")
    return figure


def _demos_and_reproduction(axes, demos, log, demo_values, log_values):
    """Demonstrations in grey, the reproduction in red, on one axis."""
    for c, demo in enumerate(demos):
        axes.plot(demo.time, demo_values(demo), color="0.6", linewidth=1.0,
                  label="demonstrations" if c == 0 else None)
    axes.plot(log.time, log_values(log), color="tab:red", linewidth=1.4, label="reproduction")


def plot_pin_reproduction(demos, log):
    """Fig. 8 (d)-(f): reproduced position, velocity and tracking force of the cotter pin.

    Parameters
    ----------
    demos : sequence of Demonstration (grey).
    log : ReproductionLog (red): ``p_WE``, ``v_WE``, ``F_tr`` against ``time``.

    Returns
    -------
    figure : matplotlib.figure.Figure, 3 x 3 axes: position, velocity, force along x, y, z.
    """
    figure = Figure(figsize=(10, 7), layout="constrained")
    grid = figure.subplots(3, 3, sharex=True)
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
    grid[0, 0].legend(loc="best", fontsize="small")
    figure.suptitle("Cotter pin: reproduced position (d), velocity (e), tracking force (f)")
    return figure


def plot_drawing_reproduction(demos, log):
    """Fig. 10: x, y, z and stiffness of the drawing demonstrations (grey) and reproduction (red).

    Parameters
    ----------
    demos : sequence of Demonstration: ``p_WE``, ``gain``.
    log : ReproductionLog: ``p_WE``, ``k_star``.

    Returns
    -------
    figure : matplotlib.figure.Figure, four axes sharing time.
    """
    figure = Figure(figsize=(8, 8), layout="constrained")
    grid = figure.subplots(4, 1, sharex=True)
    for i, axis in enumerate("xyz"):
        _demos_and_reproduction(grid[i], demos, log, lambda d, i=i: d.p_WE[:, i],
                                lambda r, i=i: r.p_WE[:, i])
        grid[i].set_ylabel(f"{axis} (m)")
    _demos_and_reproduction(grid[3], demos, log, lambda d: d.gain, lambda r: r.k_star)
    grid[3].set_ylabel("stiffness K")
    grid[3].set_xlabel("time (s)")
    grid[0].legend(loc="best", fontsize="small")
    figure.suptitle("Drawing: demonstrations and reproduction (Fig. 10)")
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
    lines = [(s, "0.7", 1.0, "demonstrations" if i == 0 else None) for i, s in enumerate(demonstrated)]
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
