"""Wire the envelope and the gain law behind any sEMG source in one call."""

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
        RmsEnvelope(window=calibration.window, per_channel=calibration.per_channel, period=period)
    )
    gain = builder.AddSystem(
        VariableGain(calibration=calibration, A_emg=A_emg, k_min=k_min, k_max=k_max)
    )
    builder.Connect(emg_output, rms.get_emg_input_port())
    builder.Connect(rms.get_envelope_output_port(), gain.get_envelope_input_port())
    return rms, gain
