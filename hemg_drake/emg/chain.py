"""Wire the envelope and the gain law behind any sEMG source in one call, and run it."""

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from hemg_drake._validate import as_seed
from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.config import MYO_PERIOD, EmgConfig
from hemg_drake.emg.envelope import RmsEnvelope
from hemg_drake.emg.gain import VariableGain
from hemg_drake.emg.synthetic import held_samples

__all__ = ["add_emg_gain_chain", "held_samples", "run_emg_chain"]


def add_emg_gain_chain(builder, emg_output, *, config=EmgConfig(), calibration=None,
                       period=MYO_PERIOD):  # fmt: skip
    """Add ``RmsEnvelope`` -> ``VariableGain`` to ``builder``, fed by ``emg_output``.

    Parameters
    ----------
    builder : pydrake.systems.framework.DiagramBuilder
    emg_output : OutputPort
        Raw sEMG, e.g. a source's ``emg`` port (8 channels for a MYO, 16 for others).
    config : EmgConfig
        The envelope's window and form (``config.envelope()``) and the gain law
        (``config.gain()``).
    calibration : EmgCalibration, optional
        Rest and MVC levels, measured with the same window and form as ``config``'s
        envelope; None: identity normalisation.
    period : float
        Sample period of the source in s.

    Returns
    -------
    rms : RmsEnvelope
    gain : VariableGain
        Its ``activation`` and ``gain`` output ports feed the controller.
    """
    envelope = config.envelope()
    if calibration is None:
        calibration = EmgCalibration(window=envelope.window, per_channel=envelope.per_channel)
    measured = (calibration.window, calibration.per_channel)
    if measured != (envelope.window, envelope.per_channel):
        raise ValueError(
            f"the calibration was measured with window={measured[0]}, per_channel="
            f"{measured[1]}, the envelope uses window={envelope.window}, per_channel="
            f"{envelope.per_channel}"
        )
    rms = builder.AddSystem(
        RmsEnvelope(config=envelope, period=period, channels=emg_output.size())
    )
    gain = builder.AddSystem(VariableGain(config=config.gain(), calibration=calibration))
    builder.Connect(emg_output, rms.get_emg_input_port())
    builder.Connect(rms.get_envelope_output_port(), gain.get_envelope_input_port())
    return rms, gain


def run_emg_chain(source, n_samples, *, seed, activation=None, config=EmgConfig(),
                  calibration=None):  # fmt: skip
    """Simulate ``source`` -> ``RmsEnvelope`` -> ``VariableGain`` and read every sample.

    The diagram runs n_samples MYO periods (200 Hz), its Context seeded with
    ``RandomGenerator(seed)``; row k of each result is what the port held after the sources'
    update k at t_k = k / 200 s.

    Parameters
    ----------
    source : System
        A new, unconnected source with an ``emg`` output port (``make_synthetic_emg_source``,
        ``make_file_emg_source``); it is added to a new diagram.
    n_samples : int
        Number of 200 Hz samples, >= 1.
    seed : int
        Seeds the Context's random sources (the synthetic source's noise).
    activation : array-like, shape (n_samples,), optional
        Muscle activation fed to a source with an ``activation`` input: sample k reads
        ``activation[k]``, so ``synthesize_emg(activation, seed)`` gives the same sEMG.
        Required for such a source, rejected for any other.
    config, calibration
        See :func:`add_emg_gain_chain`.

    Returns
    -------
    dict of ndarray
        ``time`` (n_samples,) s; ``emg`` (n_samples, 8) MYO units; ``envelope``
        (n_samples,) MYO units; ``activation`` (n_samples,) a(u) of eq. 22; ``gain``
        (n_samples,).
    """
    seed = as_seed(seed)
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
        builder.Connect(held.get_output_port(), source.GetInputPort("activation"))
    rms, gain = add_emg_gain_chain(
        builder, source.GetOutputPort("emg"), config=config, calibration=calibration
    )
    ports = {
        "emg": source.GetOutputPort("emg"),
        "envelope": rms.get_envelope_output_port(),
        "activation": gain.get_activation_output_port(),
        "gain": gain.get_gain_output_port(),
    }
    loggers = {
        name: LogVectorOutput(port, builder, publish_period=MYO_PERIOD)
        for name, port in ports.items()
    }
    diagram = builder.Build()
    simulator = Simulator(diagram)
    diagram.SetRandomContext(simulator.get_mutable_context(), RandomGenerator(seed))
    simulator.AdvanceTo(n_samples * MYO_PERIOD)
    context = simulator.get_context()
    # A logger publishing at t_k sees the port before the update at t_k: row k + 1 holds
    # sample k, and row 0 (t = 0) the zeros before the first sample.
    result = {"time": np.arange(n_samples) * MYO_PERIOD}
    for name, logger in loggers.items():
        data = logger.FindLog(context).data().T[1 : n_samples + 1]
        result[name] = data if data.shape[1] > 1 else data[:, 0]
    return result
