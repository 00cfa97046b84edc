"""The sEMG figures: Fig. 6 (the envelope) and the gain law of eq. 22."""

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
from hemg_drake.viz.figures.common import STIFFNESS_UNIT


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
