"""What every figure shares: :func:`save_figure`, the stiffness's unit and labels, and a
plot of signals against time."""

import io
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from hemg_drake.control.pd import STIFFNESS_SCALE
from hemg_drake.fileio import write_bytes_atomic

# K is a gain: joint j of the slave's PD gets the stiffness k_j = K s_j N·m/rad, with s_j
# from ``hemg_drake.control.pd.STIFFNESS_SCALE`` (20 at the shoulder ... 0.1 at the last wrist
# roll). So K is the stiffness of a joint with s_j = 1, in N·m/rad.
STIFFNESS_UNIT = "N·m/rad per unit s_j"
STIFFNESS_LABEL = f"stiffness K\n({STIFFNESS_UNIT})"
# Below the panel, for readers who do not know s_j.
STIFFNESS_NOTE = "K sets joint j's PD stiffness to K·s_j N·m/rad, s = ({})".format(
    ", ".join(f"{s:g}" for s in STIFFNESS_SCALE))


def save_figure(figure, path, *, dpi=150):
    """Write ``figure`` to ``path`` atomically; the format follows the suffix (.png, .svg, .pdf)."""
    path = Path(path)
    buffer = io.BytesIO()
    figure.savefig(buffer, format=path.suffix.lstrip(".").lower() or "png", dpi=dpi)
    write_bytes_atomic(path, buffer.getvalue())


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
