"""The paper's figures, as plain functions returning matplotlib Figures.

Figures are built with ``matplotlib.figure.Figure`` (no pyplot state), so they
work under any backend; ``save_figure`` writes one atomically.
"""

import io
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from hemg_drake.emg.envelope import moving_rms
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
