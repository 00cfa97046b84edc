"""Moving-RMS envelope of the sEMG (eqs. 1-2): an offline function and its system.

Both forms treat the samples before the start as zeros and always divide by the
window length, so the first ``window - 1`` envelope values ramp up from the
first sample rather than being undefined.
"""

import math

import numpy as np
from pydrake.systems.framework import LeafSystem

from hemg_drake._validate import as_scalar
from hemg_drake.emg.sources import MYO_CHANNELS, MYO_PERIOD


def _check_window(window):
    if isinstance(window, (int, np.integer)) and not isinstance(window, bool) and window >= 1:
        return int(window)
    raise ValueError(f"window must be a positive integer, got {window!r}")


def _squares(samples, per_channel):
    """Squares of the signal eq. 2 averages: of the channel sum (eq. 1) or per channel."""
    if per_channel:
        return np.square(samples, dtype=float)
    return np.square(samples.sum(axis=1, keepdims=True, dtype=float))


def _combine(mean_squares):
    """RMS per column, summed over columns (one column unless per channel)."""
    return np.sqrt(mean_squares).sum(axis=-1)


# The paper's moving-RMS window L_win (200 Hz samples): the default everywhere.
DEFAULT_WINDOW = 20

def moving_rms(samples, window=DEFAULT_WINDOW, *, per_channel=False):
    """Moving-window RMS envelope of multichannel sEMG (eqs. 1-2).

    By default, the paper's form: u_k = sum_i samples[k, i] (eq. 1), then
    rms_k = sqrt((1 / L) sum_{j=k-L+1..k} u_j^2) (eq. 2). With
    ``per_channel=True``, the RMS of each channel over the window, summed over
    channels (signed channel sums partly cancel; per-channel RMS does not).

    Samples before the first are taken as zeros, and the sum is always divided
    by ``window``, so ``rms[:window - 1]`` ramps up from the first sample.

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
    # Integer recordings (the MYO's int8) are used as they are: no float copy.
    if samples.dtype.kind == "f" and not np.all(np.isfinite(samples)):
        raise ValueError("samples contain NaN or infinite values")
    squares = _squares(samples, per_channel)
    # Each window summed on its own (the current square plus the window - 1
    # earlier ones, zeros before the start): exact for integer samples, and
    # free of the cancellation of a difference of cumulative sums.
    sums = squares.copy()
    for lag in range(1, window):
        sums[lag:] += squares[:-lag]
    return _combine(sums / window)


class RmsEnvelope(LeafSystem):
    """Moving-window RMS of 8-channel sEMG, in O(1) per sample (eqs. 1-2).

    .. pydrake_system::

        name: RmsEnvelope
        input_ports:
        - emg
        output_ports:
        - envelope

    ``emg`` is the raw sEMG (8 channels, MYO units), ``envelope`` the RMS in the
    same units: of the channel sum by default (eq. 1 then eq. 2), or the
    per-channel RMS summed over channels with ``per_channel=True``.

    Timing: a periodic discrete update every ``period`` reads the input, adds
    its square to a ring buffer of the last ``window`` squares with a running
    sum, and stores the envelope, which the output holds until the next update.
    The update runs half a period after the sources' updates (offset
    ``period / 2``; sources update at t_k = k * period), so it reads sample k
    whether the source is discrete or a held signal, and envelope k is output
    from t_k + period / 2. Fed by any source of this package, the output is
    sample for sample ``moving_rms`` of the source's samples (zeros before the
    start, divided by L_win throughout): exactly for integer samples, to
    rounding otherwise.

    Modelling choice: the running sum is recomputed from the buffer each time
    the ring wraps, so rounding (non-integer input) cannot drift, and a NaN
    sample makes the envelope NaN for at most 2 L_win samples (``VariableGain``
    maps a NaN envelope to K_min).

    Parameters
    ----------
    window : int
        L_win, samples per window (default 20, the paper's choice).
    per_channel : bool
        Per-channel RMS summed over channels instead of the RMS of the sum.
    period : float
        Sample period in s (MYO: 1/200).
    channels : int
        Values per sample (MYO: 8; other armbands 16, in volts).
    """

    def __init__(
        self, *, window=DEFAULT_WINDOW, per_channel=False, period=MYO_PERIOD,
        channels=MYO_CHANNELS,
    ):  # fmt: skip
        LeafSystem.__init__(self)
        self._window = _check_window(window)
        self._per_channel = bool(per_channel)
        if isinstance(channels, bool) or not isinstance(channels, (int, np.integer)) or channels < 1:
            raise ValueError(f"channels must be a positive integer, got {channels!r}")
        self._columns = int(channels) if per_channel else 1
        period = as_scalar("period", period)
        self._emg_input = self.DeclareVectorInputPort("emg", int(channels))
        # Layout: ring of squares (window x columns, row-major), running sum
        # (columns), index of the oldest row.
        self._ring_state = self.DeclareDiscreteState((self._window + 1) * self._columns + 1)
        self._envelope_state = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=period, offset_sec=period / 2, update=self._update_envelope
        )
        self._envelope_output = self.DeclareStateOutputPort("envelope", self._envelope_state)

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

    def _update_envelope(self, context, discrete_state):
        # Plain floats: numpy's per-call overhead on a few numbers costs more than the sums,
        # which are the same (exact for integer samples, as moving_rms's).
        state = context.get_discrete_state(self._ring_state).value().tolist()
        emg = self._emg_input.Eval(context).tolist()
        window, columns = self._window, self._columns
        squares = [x * x for x in emg] if self._per_channel else [sum(emg) ** 2]
        oldest = int(state[-1])
        row = oldest * columns
        totals = state[window * columns : -1]
        totals = [t + q - r for t, q, r in zip(totals, squares, state[row : row + columns])]
        state[row : row + columns] = squares
        oldest = (oldest + 1) % window
        if oldest == 0:
            totals = [sum(state[c : window * columns : columns]) for c in range(columns)]
        state[window * columns : -1] = totals
        state[-1] = oldest
        discrete_state.set_value(self._ring_state, state)
        # Rounding of non-integer input must not push a zero sum below zero.
        if columns == 1:
            envelope = math.sqrt(max(totals[0], 0.0) / window)
        else:
            envelope = float(_combine(np.maximum(totals, 0.0) / window))
        discrete_state.set_value(self._envelope_state, [envelope])
