"""Wire the envelope and the gain law behind any sEMG source in one call, and run it."""

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.envelope import RmsEnvelope
from hemg_drake.emg.gain import A_EMG, DEFAULT_K_MAX, DEFAULT_K_MIN, VariableGain
from hemg_drake.emg.sources import MYO_PERIOD


def add_emg_gain_chain(
    builder,
    emg_output,
    *,
    calibration=None,
    A_emg=A_EMG,
    k_min=DEFAULT_K_MIN,
    k_max=DEFAULT_K_MAX,
    period=MYO_PERIOD,
):
    """Add ``RmsEnvelope`` -> ``VariableGain`` to ``builder``, fed by ``emg_output``.

    The envelope takes its window and form from the calibration, so the raw
    envelope is normalised with levels measured the same way.

    Parameters
    ----------
    builder : pydrake.systems.framework.DiagramBuilder
    emg_output : OutputPort
        8-channel raw sEMG, e.g. ``SyntheticEmgSource.get_emg_output_port()``.
    calibration : EmgCalibration, optional
        None: L_win = 20, paper form, identity normalisation.
    A_emg, k_min, k_max
        See ``VariableGain``.
    period : float
        Sample period of the source in s.

    Returns
    -------
    rms : RmsEnvelope
    gain : VariableGain
        Its ``activation`` and ``gain`` output ports feed the controller.
    """
    calibration = EmgCalibration() if calibration is None else calibration
    rms = builder.AddSystem(
        RmsEnvelope(
            window=calibration.window, per_channel=calibration.per_channel, period=period,
            channels=emg_output.size(),  # 8 for a MYO, 16 for other armbands
        )  # fmt: skip
    )
    gain = builder.AddSystem(
        VariableGain(calibration=calibration, A_emg=A_emg, k_min=k_min, k_max=k_max)
    )
    builder.Connect(emg_output, rms.get_emg_input_port())
    builder.Connect(rms.get_envelope_output_port(), gain.get_envelope_input_port())
    return rms, gain


def held_samples(values):
    """A source holding ``values[k]`` around each 200 Hz sample instant t_k = k / 200 s.

    Its breaks sit a quarter period before each sample instant, away from the sources'
    updates (t_k) and the envelope's (t_k + T/2), so every system of the chain reads
    ``values[k]`` for sample k whatever the rounding of k * T.

    Parameters
    ----------
    values : array-like, shape (n_samples,) or (n_samples, size)

    Returns
    -------
    TrajectorySource
        Its output has size 1, or ``size``; after the last sample it holds the last row.
    """
    values = np.asarray(values, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    breaks = np.concatenate([[0.0], (np.arange(1, len(values) + 1) - 0.25) * MYO_PERIOD])
    knots = np.vstack([values, values[-1:]]).T
    return TrajectorySource(PiecewisePolynomial.ZeroOrderHold(breaks, knots))


def run_emg_chain(
    source,
    n_samples,
    *,
    activation=None,
    calibration=None,
    A_emg=A_EMG,
    k_min=DEFAULT_K_MIN,
    k_max=DEFAULT_K_MAX,
):
    """Simulate ``source`` -> ``RmsEnvelope`` -> ``VariableGain`` and read every sample.

    The diagram runs n_samples MYO periods (200 Hz); row k of each result is what the port
    held after the sources' update k at t_k = k / 200 s.

    Parameters
    ----------
    source : SyntheticEmgSource or FileEmgSource
        A new, unconnected source (it is added to a new diagram).
    n_samples : int
        Number of 200 Hz samples, >= 1.
    activation : array-like, shape (n_samples,), optional
        Muscle activation fed to a source with an ``activation`` input: sample k reads
        ``activation[k]``, so ``synthesize_emg(activation, seed)`` gives the same sEMG.
        Required for such a source, rejected for any other.
    calibration, A_emg, k_min, k_max
        See :func:`add_emg_gain_chain`.

    Returns
    -------
    dict of ndarray
        ``time`` (n_samples,) s; ``emg`` (n_samples, 8) MYO units; ``envelope``
        (n_samples,) MYO units; ``activation`` (n_samples,) a(u) of eq. 22; ``gain``
        (n_samples,).
    """
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise ValueError(f"n_samples must be a positive integer, got {n_samples!r}")
    has_input = source.num_input_ports() > 0
    if has_input and activation is None:
        raise ValueError("this source has an activation input: pass activation=")
    if not has_input and activation is not None:
        raise ValueError("this source has no activation input: leave activation out")
    builder = DiagramBuilder()
    builder.AddSystem(source)
    if has_input:
        values = np.asarray(activation, dtype=float)
        if values.shape != (n_samples,) or np.any(np.isnan(values)):
            raise ValueError(
                f"activation must be {n_samples} numbers without NaN, got shape {values.shape}"
            )
        held = builder.AddSystem(held_samples(values))
        builder.Connect(held.get_output_port(), source.get_activation_input_port())
    rms, gain = add_emg_gain_chain(
        builder,
        source.get_emg_output_port(),
        calibration=calibration,
        A_emg=A_emg,
        k_min=k_min,
        k_max=k_max,
    )
    ports = {
        "emg": source.get_emg_output_port(),
        "envelope": rms.get_envelope_output_port(),
        "activation": gain.get_activation_output_port(),
        "gain": gain.get_gain_output_port(),
    }
    loggers = {
        name: LogVectorOutput(port, builder, publish_period=MYO_PERIOD)
        for name, port in ports.items()
    }
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(n_samples * MYO_PERIOD)
    context = simulator.get_context()
    # A logger publishing at t_k sees the port before the update at t_k: row k + 1 holds
    # sample k, and row 0 (t = 0) the zeros before the first sample.
    result = {"time": np.arange(n_samples) * MYO_PERIOD}
    for name, logger in loggers.items():
        data = logger.FindLog(context).data().T[1 : n_samples + 1]
        result[name] = data if data.shape[1] > 1 else data[:, 0]
    return result
