"""Moving-RMS envelope of the sEMG (eqs. 1-2): the law, and the system that applies it.

The law is two functions, :func:`emg_squares` (eq. 1, squared) and :func:`window_rms`
(eq. 2 on one window of squares). ``RmsEnvelope`` keeps the last ``window`` squares in its
discrete state and outputs ``window_rms`` of them; :func:`moving_rms` applies the same two
functions to every window of a recording at once (Fig. 6, calibration). Samples before the
start count as zeros and the sum is always divided by the window length, so the first
``window - 1`` values ramp up from the first sample rather than being undefined.
"""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake._validate import as_scalar
from hemg_drake.emg.config import MYO_CHANNELS, MYO_PERIOD, EnvelopeConfig

# The paper's moving-RMS window L_win (200 Hz samples).
DEFAULT_WINDOW = EnvelopeConfig.window


def _check_window(window):
    if isinstance(window, (int, np.integer)) and not isinstance(window, bool) and window >= 1:
        return int(window)
    raise ValueError(f"window must be a positive integer, got {window!r}")


def emg_squares(samples, per_channel):
    """The squares eq. 2 averages, per sample: of the channel sum u_k (eq. 1) or per channel.

    Parameters
    ----------
    samples : ndarray, shape (n_samples, n_channels)
    per_channel : bool

    Returns
    -------
    squares : ndarray, shape (n_samples, n_channels) if per_channel else (n_samples, 1)
    """
    if per_channel:
        return samples * samples
    u = samples.sum(axis=-1, keepdims=True)
    return u * u


def window_rms(squares):
    """Eq. 2 on windows of squares: sqrt of the mean over the window, summed over columns.

    Parameters
    ----------
    squares : ndarray, shape (..., window, columns)
        From :func:`emg_squares`, oldest first (one column for the paper's form).

    Returns
    -------
    rms : ndarray, shape (...)
    """
    window = squares.shape[-2]
    # A sum of integer squares is exact in any order; rounding of non-integer input must not
    # take a zero sum below zero.
    return np.sqrt(np.maximum(squares.sum(axis=-2) / window, 0.0)).sum(axis=-1)


def moving_rms(samples, window=DEFAULT_WINDOW, *, per_channel=False):
    """Moving-window RMS envelope of multichannel sEMG (eqs. 1-2).

    By default, the paper's form: u_k = sum_i samples[k, i] (eq. 1), then
    rms_k = sqrt((1 / L) sum_{j=k-L+1..k} u_j^2) (eq. 2). With ``per_channel=True``, the
    RMS of each channel over the window, summed over channels (signed channel sums partly
    cancel; per-channel RMS does not). Samples before the first are taken as zeros, and the
    sum is always divided by ``window``, so ``rms[:window - 1]`` ramps up from the first
    sample. ``RmsEnvelope`` outputs the same numbers sample for sample (same functions).

    Parameters
    ----------
    samples : array-like, shape (n_samples, n_channels)
        Raw sEMG, oldest first (MYO: 8 channels, integers in -128..127).
    window : int
        L_win, the number of samples in the window (paper: 10, 20, 30; 20 chosen).
    per_channel : bool
        Per-channel RMS summed over channels instead of the RMS of the sum.

    Returns
    -------
    rms : ndarray, shape (n_samples,)
        The envelope, in the units of ``samples``.
    """
    window = _check_window(window)
    samples = np.asarray(samples)
    if not (np.issubdtype(samples.dtype, np.integer) or np.issubdtype(samples.dtype, np.floating)):
        samples = samples.astype(float)
    if samples.ndim != 2 or samples.shape[0] == 0:
        raise ValueError(
            f"samples must have shape (n_samples, n_channels) with n_samples > 0, "
            f"got {samples.shape}"
        )
    if samples.dtype.kind == "f" and not np.all(np.isfinite(samples)):
        raise ValueError("samples contain NaN or infinite values")
    squares = emg_squares(samples.astype(float), per_channel)
    padded = np.concatenate([np.zeros((window - 1, squares.shape[1])), squares])
    # Every window as a view, shape (n_samples, window, columns): no copy.
    windows = np.lib.stride_tricks.sliding_window_view(padded, window, axis=0).swapaxes(-1, -2)
    return window_rms(windows)


@TemplateSystem.define("RmsEnvelope_", T_list=(float, AutoDiffXd))
def RmsEnvelope_(T):
    class Impl(LeafSystem_[T]):
        """Moving-window RMS of multichannel sEMG (eqs. 1-2).

        .. pydrake_system::

            name: RmsEnvelope
            input_ports:
            - emg
            output_ports:
            - envelope

        ``emg`` is the raw sEMG (``channels`` values, MYO units), ``envelope`` (1) the RMS in
        the same units: of the channel sum by default (eq. 1 then eq. 2), or the per-channel
        RMS summed over channels with ``config.per_channel``.

        Timing: a periodic discrete update every ``period`` pushes the input's square
        (:func:`emg_squares`) into the window of the last L_win squares (the discrete state,
        oldest first); ``envelope`` is :func:`window_rms` of that state. The update runs half
        a period after the sources' (offset ``period / 2``; sources update at t_k = k *
        period), so it reads sample k whether the source is discrete or a held signal, and
        envelope k is output from t_k + period / 2: sample for sample ``moving_rms`` of the
        source's samples (zeros before the start, divided by L_win throughout). A NaN sample
        makes the envelope NaN for L_win samples (``VariableGain`` reads it as rest).

        Parameters
        ----------
        config : EnvelopeConfig
            L_win and the form.
        period : float
            Sample period of the source in s (MYO: 1/200).
        channels : int
            Values per sample (MYO: 8; other armbands 16, in volts).
        """

        def _construct(self, *, config=EnvelopeConfig(), period=MYO_PERIOD,
                       channels=MYO_CHANNELS, converter=None):  # fmt: skip
            LeafSystem_[T].__init__(self, converter)
            self._config = config
            self._window = _check_window(config.window)
            self._per_channel = bool(config.per_channel)
            if isinstance(channels, bool) or not isinstance(channels, (int, np.integer)) or channels < 1:
                raise ValueError(f"channels must be a positive integer, got {channels!r}")
            self._channels = int(channels)
            self._period = as_scalar("period", period)
            self._columns = self._channels if self._per_channel else 1
            self._emg_input = self.DeclareVectorInputPort("emg", self._channels)
            # The last L_win squares, oldest first, row-major (window x columns).
            self._window_state = self.DeclareDiscreteState(self._window * self._columns)
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=self._period, offset_sec=self._period / 2, update=self._push
            )
            self._envelope_output = self.DeclareVectorOutputPort(
                "envelope", 1, self._calc_envelope,
                prerequisites_of_calc={self.discrete_state_ticket(self._window_state)},
            )  # fmt: skip

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, config=other._config, period=other._period,
                            channels=other._channels, converter=converter)  # fmt: skip

        @property
        def window(self):
            """L_win, samples per window."""
            return self._window

        @property
        def per_channel(self):
            """True for the per-channel form."""
            return self._per_channel

        def get_emg_input_port(self):
            return self._emg_input

        def get_envelope_output_port(self):
            return self._envelope_output

        def _push(self, context, discrete_state):
            squares = emg_squares(self._emg_input.Eval(context)[np.newaxis, :], self._per_channel)
            window = context.get_discrete_state(self._window_state).CopyToVector()
            discrete_state.set_value(
                self._window_state, np.concatenate([window[self._columns :], squares[0]])
            )

        def _calc_envelope(self, context, output):
            window = context.get_discrete_state(self._window_state).CopyToVector()
            output.SetAtIndex(0, window_rms(window.reshape(self._window, self._columns)))

    return Impl


RmsEnvelope = RmsEnvelope_[None]
