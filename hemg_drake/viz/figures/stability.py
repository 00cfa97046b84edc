"""The teleoperation loop's spectral radius against the transport delay
(:mod:`hemg_drake.analysis.stability`)."""

import numpy as np
from matplotlib.figure import Figure


def plot_loop_stability(curves, *, simulated_onset_ms=None, title=None):
    """Spectral radius of the linearised loop against the one-way delay, one line per case.

    Parameters
    ----------
    curves : dict of str to list of LoopSpectrum
        Label (e.g. "force, K = 10") -> the spectra of :func:`loop_stability`.
    simulated_onset_ms : float, optional
        Where the simulation saw the loop start to oscillate: a dashed vertical line.
    title : str, optional

    Returns
    -------
    figure : matplotlib.figure.Figure
    """
    if not curves:
        raise ValueError("curves must hold at least one case")
    figure = Figure(figsize=(7.0, 4.0), layout="constrained")
    axis = figure.add_subplot()
    for label, results in curves.items():
        results = sorted(results, key=lambda r: r.delay_ms)
        delays = np.array([r.delay_ms for r in results])
        radii = np.array([r.spectral_radius for r in results])
        axis.plot(delays, radii - 1.0, marker="o", markersize=3, label=label)
    axis.axhline(0.0, color="black", linewidth=0.8)
    if simulated_onset_ms is not None:
        axis.axvline(
            simulated_onset_ms, color="grey", linestyle="--",
            label=f"simulated onset ({simulated_onset_ms:g} ms)",
        )  # fmt: skip
    axis.set_xlabel("one-way delay, each way (ms)")
    axis.set_ylabel("spectral radius - 1 (> 0: unstable)")
    axis.set_title(title or "teleoperation loop about a hold, linearised")
    axis.legend(fontsize="small")
    return figure
