"""Sources of 8-channel raw sEMG at 200 Hz, MYO-like: synthetic, file replay, live.

Every source outputs the MYO's raw samples: 8 channels, integers in the signed
8-bit range -128..127 (carried as float64 in Drake vector ports), one sample per
1/200 s (facts: ``docs/facts.md``, MYO section). Sample k is output
from the discrete update at t = k / 200 s until the next one, and the output is
zero before the first; as with any Drake discrete update, a logger publishing
at exactly t = k / 200 still sees sample k - 1.

``LiveEmgSource`` takes the channel count and units as parameters (8 int8 channels by
default; e.g. 16 channels in volts from an armband that LibEMG streams) and emits every
sample the device delivered, in order, through a queue (its docstring gives the policy).
"""

import collections
import math
from pathlib import Path

import numpy as np
from pydrake.systems.framework import LeafSystem

from hemg_drake._validate import as_scalar, as_seed
from hemg_drake.fileio import load_npz, save_npz_atomic, write_text_atomic

MYO_CHANNELS = 8
MYO_RATE = 200.0
MYO_PERIOD = 1.0 / MYO_RATE
INT8_MIN, INT8_MAX = -128, 127

# Electrodes around the forearm see the contracting muscle unequally: the pods
# over the muscle belly (first and last here) most, those across the arm least.
DEFAULT_CHANNEL_GAINS = (40.0, 34.0, 26.0, 20.0, 20.0, 26.0, 34.0, 40.0)
# Standard deviation at rest (electrode and amplifier noise), in MYO units.
DEFAULT_REST_STD = 2.0
NPZ_KEY = "emg"
# Samples whose noise is drawn from one generator (one second at 200 Hz).
NOISE_BLOCK = 200


class _NoiseModel:
    """The synthetic source's law, shared by the system and its numpy twin."""

    def __init__(self, seed, channel_gains, rest_std, exponent):
        self.seed = as_seed(seed)
        self.gains = np.asarray(channel_gains, dtype=float)
        if self.gains.shape != (MYO_CHANNELS,) or not np.all(
            np.isfinite(self.gains) & (self.gains >= 0)
        ):
            raise ValueError(
                f"channel_gains must be {MYO_CHANNELS} finite non-negative numbers, "
                f"got {channel_gains!r}"
            )
        if not (np.isfinite(rest_std) and rest_std >= 0):
            raise ValueError(f"rest_std must be finite and >= 0, got {rest_std!r}")
        if not (np.isfinite(exponent) and exponent > 0):
            raise ValueError(f"exponent must be finite and > 0, got {exponent!r}")
        self.rest_std = float(rest_std)
        self.exponent = float(exponent)
        self._block, self._noise = None, None
        self._gain_list = self.gains.tolist()

    def sample(self, activation, k):
        """Sample number ``k`` for a muscle activation in [0, 1]: 8 integer-valued floats."""
        level = activation**self.exponent
        # Plain floats (200 Hz, 8 numbers); round() rounds half to even, as np.round does.
        return [
            min(max(float(round((self.rest_std + gain * level) * noise)), INT8_MIN), INT8_MAX)
            for gain, noise in zip(self._gain_list, self.noise(k).tolist())
        ]

    def noise(self, k):
        """Unit Gaussian noise of sample ``k``, shape (8,): a pure function of (seed, k).

        Drawn a block of ``NOISE_BLOCK`` samples at a time from
        ``np.random.default_rng((seed, k // NOISE_BLOCK))`` and cached, so that the system
        and its twin agree exactly whatever the step sizes, without building a generator
        per sample (which cost more than the rest of the 200 Hz chain).
        """
        block, row = divmod(k, NOISE_BLOCK)
        if block != self._block:
            generator = np.random.default_rng((self.seed, block))
            self._noise = generator.standard_normal((NOISE_BLOCK, MYO_CHANNELS))
            self._block = block
        return self._noise[row]


def synthesize_emg(
    activation,
    seed,
    *,
    channel_gains=DEFAULT_CHANNEL_GAINS,
    rest_std=DEFAULT_REST_STD,
    exponent=1.0,
):
    """Synthetic MYO-like raw sEMG for a sequence of muscle activations.

    The numpy twin of ``SyntheticEmgSource``: the same arguments give exactly
    the same samples as the system (see its docstring for the model).

    Parameters
    ----------
    activation : array-like, shape (n_samples,)
        Muscle activation per 200 Hz sample; clipped to [0, 1]. NaN is rejected.
    seed : int
        Non-negative seed; the same seed gives the same samples.
    channel_gains : array-like, shape (8,)
        Noise standard deviation added per channel at full activation (MYO units).
    rest_std : float
        Noise standard deviation at rest, on every channel (MYO units).
    exponent : float
        p in std = rest_std + gain * activation^p.

    Returns
    -------
    emg : ndarray of int64, shape (n_samples, 8)
        Integers in -128..127.
    """
    activation = np.asarray(activation, dtype=float)
    if activation.ndim != 1:
        raise ValueError(f"activation must have shape (n_samples,), got {activation.shape}")
    if np.any(np.isnan(activation)):
        raise ValueError("activation contains NaN")
    model = _NoiseModel(seed, channel_gains, rest_std, exponent)
    clipped = np.clip(activation, 0.0, 1.0)
    emg = np.zeros((len(activation), MYO_CHANNELS), dtype=np.int64)
    for k, a in enumerate(clipped):
        emg[k] = model.sample(a, k)
    return emg


class _SampledSource(LeafSystem):
    """What every sEMG source shares: sample k is taken at t = k * period and held.

    Subclasses implement ``_sample(context, k)``, returning the ``channels`` values of
    sample k, or None to keep the last one.
    """

    def __init__(self, period, channels=MYO_CHANNELS):
        LeafSystem.__init__(self)
        self._emg_state = self.DeclareDiscreteState(channels)
        self._count_state = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=as_scalar("period", period), offset_sec=0.0, update=self._update_sample
        )
        self._emg_output = self.DeclareStateOutputPort("emg", self._emg_state)

    def get_emg_output_port(self):
        return self._emg_output

    def _update_sample(self, context, discrete_state):
        k = int(context.get_discrete_state(self._count_state).GetAtIndex(0))
        sample = self._sample(context, k)
        if sample is not None:
            discrete_state.set_value(self._emg_state, sample)
        discrete_state.set_value(self._count_state, [k + 1])


class SyntheticEmgSource(_SampledSource):
    """Synthetic MYO-like raw sEMG whose amplitude grows with muscle activation.

    .. pydrake_system::

        name: SyntheticEmgSource
        input_ports:
        - activation
        output_ports:
        - emg

    ``activation`` (1, unitless) is the muscle activation; it is clipped to
    [0, 1], and a NaN reads as 0 (rest). ``emg`` (8, MYO units) holds integers
    in -128..127.

    Model (Sec. II-B; a stand-in for the MYO, not a physiological model): each
    channel i is zero-mean Gaussian noise with standard deviation
    std_i = rest_std + channel_gains[i] * activation^exponent, rounded to an
    integer and clipped to int8. With the default exponent 1 the RMS envelope
    of the channel sum grows linearly with activation (up to clipping, which is
    rare below 3 std = 127), so after an ``EmgCalibration`` from rest
    (activation 0) and MVC (activation 1) recordings, the normalised envelope
    is close to the activation itself: roughly monotone and near identity.

    Timing: a periodic discrete update at 200 Hz (offset 0) reads the input and
    draws sample k at t = k / 200; the output holds it until the next update.
    Sample k's noise is row k mod 200 of 200 x 8 normals drawn from
    ``np.random.default_rng((seed, k // 200))``, so the same seed gives the same
    samples, and ``synthesize_emg`` with the input
    sampled at the same instants gives exactly the same samples.

    Parameters
    ----------
    seed : int
        Non-negative seed.
    channel_gains, rest_std, exponent
        See ``synthesize_emg``.
    period : float
        Sample period in s (MYO: 1/200).
    """

    def __init__(
        self,
        *,
        seed,
        channel_gains=DEFAULT_CHANNEL_GAINS,
        rest_std=DEFAULT_REST_STD,
        exponent=1.0,
        period=MYO_PERIOD,
    ):
        _SampledSource.__init__(self, period)
        self._model = _NoiseModel(seed, channel_gains, rest_std, exponent)
        self._activation_input = self.DeclareVectorInputPort("activation", 1)

    def get_activation_input_port(self):
        return self._activation_input

    def _sample(self, context, k):
        activation = float(self._activation_input.Eval(context)[0])
        activation = 0.0 if math.isnan(activation) else min(max(activation, 0.0), 1.0)
        return self._model.sample(activation, k)


def _int8_problem(value):
    if not INT8_MIN <= value <= INT8_MAX:
        return f"value {value} is outside the int8 range {INT8_MIN}..{INT8_MAX}"
    return None


def _int8_array_problem(emg):
    """What is wrong with the first value of ``emg`` (2-D) that is not an int8 integer, or None."""
    if not np.issubdtype(emg.dtype, np.number) or np.issubdtype(emg.dtype, np.complexfloating):
        return f"array {NPZ_KEY!r} has non-numeric dtype {emg.dtype}"
    checks = (
        (np.isnan(emg), "NaN"),
        (~np.isfinite(emg), "an infinite value"),
        (np.round(emg) != emg, "a non-integer value"),
        ((emg < INT8_MIN) | (emg > INT8_MAX), f"a value outside {INT8_MIN}..{INT8_MAX}"),
    )
    for bad, what in checks:
        if np.any(bad):
            row, column = np.argwhere(bad)[0]
            return f"row {row + 1}, column {column + 1}: {what} ({emg[row, column]})"
    return None


def _load_csv(path):
    rows = []
    with open(path, encoding="utf-8") as f:
        for line_number, line in enumerate(f, start=1):
            if not line.strip():
                continue
            fields = line.split(",")
            where = f"{path}: line {line_number}"
            if len(fields) != MYO_CHANNELS:
                raise ValueError(
                    f"{where}: expected {MYO_CHANNELS} comma-separated columns, found {len(fields)}"
                )
            row = []
            for column, field in enumerate(fields, start=1):
                try:
                    value = int(field.strip())
                except ValueError:
                    raise ValueError(
                        f"{where}: column {column}: {field.strip()!r} is not an integer"
                    ) from None
                problem = _int8_problem(value)
                if problem:
                    raise ValueError(f"{where}: column {column}: {problem}")
                row.append(value)
            rows.append(row)
    return np.array(rows, dtype=np.int64).reshape(-1, MYO_CHANNELS)


def _load_npz(path):
    arrays = load_npz(path, kind="sEMG recording")
    if NPZ_KEY not in arrays:
        raise ValueError(f"{path}: no array named {NPZ_KEY!r} (found {sorted(arrays)})")
    emg = arrays[NPZ_KEY]
    if emg.ndim != 2 or emg.shape[1] != MYO_CHANNELS:
        raise ValueError(
            f"{path}: array {NPZ_KEY!r} must have shape (n_samples, {MYO_CHANNELS}), "
            f"got {emg.shape}"
        )
    problem = _int8_array_problem(emg)
    if problem:
        raise ValueError(f"{path}: {problem}")
    return emg.astype(np.int64)


def load_emg_recording(path):
    """Read a raw sEMG recording: CSV (8 integer columns, no header) or NPZ.

    CSV: one 200 Hz sample per line, 8 comma-separated integers in -128..127,
    no header (the layout of public MYO data sets); blank lines are skipped.
    NPZ (``.npz`` suffix): an array named ``"emg"`` of shape (n_samples, 8)
    holding integer values in -128..127 (any numeric dtype).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    emg : ndarray of int64, shape (n_samples, 8)

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        The file is malformed; the message names the file, the line (CSV) or
        row (NPZ) and the problem.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"EMG recording not found: {path}")
    emg = _load_npz(path) if path.suffix.lower() == ".npz" else _load_csv(path)
    if len(emg) == 0:
        raise ValueError(f"{path}: the recording holds no samples")
    return emg


def save_emg_recording(path, emg):
    """Write raw sEMG atomically in the layout ``load_emg_recording`` reads.

    Parameters
    ----------
    path : str or Path
        ``.npz``: an array named ``"emg"``; any other suffix: CSV, 8 integer
        columns, no header.
    emg : array-like, shape (n_samples, 8)
        Integers in -128..127, at least one sample.
    """
    emg = np.asarray(emg)
    if emg.ndim != 2 or emg.shape[1] != MYO_CHANNELS or len(emg) == 0:
        raise ValueError(
            f"emg must have shape (n_samples >= 1, {MYO_CHANNELS}), got {emg.shape}"
        )
    problem = _int8_array_problem(emg)
    if problem:
        raise ValueError(f"emg must hold finite integers in {INT8_MIN}..{INT8_MAX}: {problem}")
    emg = emg.astype(np.int64)
    path = Path(path)
    if path.suffix.lower() == ".npz":
        save_npz_atomic(path, **{NPZ_KEY: emg.astype(np.int8)})
    else:
        write_text_atomic(path, "".join(",".join(map(str, row)) + "\n" for row in emg))


class FileEmgSource(_SampledSource):
    """Replays a raw sEMG recording at 200 Hz.

    .. pydrake_system::

        name: FileEmgSource
        output_ports:
        - emg

    ``emg`` (8, MYO units): row k of the recording (``load_emg_recording``) from
    t = k * period until the next update; the file is read and checked when the
    system is built, so a malformed file fails there, never mid-simulation.

    Timing: periodic discrete update every ``period`` (offset 0). After the
    last row, ``at_end="hold"`` keeps outputting it; ``at_end="loop"`` starts
    again from the first row.

    Parameters
    ----------
    filename : str or Path
        CSV or NPZ recording (see ``load_emg_recording``).
    at_end : {"hold", "loop"}
    period : float
        Sample period in s (MYO: 1/200).
    """

    def __init__(self, *, filename, at_end="hold", period=MYO_PERIOD):
        if at_end not in ("hold", "loop"):
            raise ValueError(f"at_end must be 'hold' or 'loop', got {at_end!r}")
        self._recording = load_emg_recording(filename).astype(float)
        self._loop = at_end == "loop"
        _SampledSource.__init__(self, period)

    def _sample(self, context, k):
        n = len(self._recording)
        return self._recording[k % n if self._loop else min(k, n - 1)]


# Units of a live device's samples: how they are checked and clipped.
# "int8": the MYO's raw ADC counts, clipped to -128..127 (a driver may hand out wider ints);
# "V": volts, as LibEMG's streamers of Delsys, SiFi or OYMotion armbands give them, unclipped.
LIVE_UNITS = ("int8", "V")
# Samples kept waiting at most (1 s at 200 Hz) before the oldest are dropped: a backlog that
# long means the simulation runs persistently slower than real time.
DEFAULT_MAX_BACKLOG = 200
# The counters a LiveEmgSource keeps, in the order of its ``counters`` output port.
LIVE_COUNTERS = ("received", "emitted", "underruns", "dropped", "backlog", "device_lost")


class EmgDeviceStalled(RuntimeError):
    """A live sEMG device delivered nothing for longer than the source's ``timeout``."""


class LiveEmgSource(_SampledSource):
    """Emits every raw sEMG sample a live armband delivered, in order, one per period.

    .. pydrake_system::

        name: LiveEmgSource
        output_ports:
        - emg
        - counters

    ``emg`` (``channels``; MYO units by default, or volts): the next sample of the queue at
    each poll, held between polls, zero before the first. ``counters`` (6): the totals of
    ``LIVE_COUNTERS`` after the last poll (``counters_dict`` names them).

    The device is any object with ``read_samples()`` (preferred) or ``read_emg()``,
    returning None when nothing arrived, one sample (shape (channels,)) or every sample
    since the last call (shape (n, channels), oldest first). ``open_myo_device()`` gives
    one for a MYO, ``hemg_drake.emg.libemg.LibEmgSharedMemory`` one for any armband that a
    LibEMG streamer publishes; an optional attribute ``lost`` (samples the device itself
    lost, e.g. overwritten in LibEMG's ring buffer before they were read) is reported too.

    Queue policy (the device's clock and the simulator's drift apart; no sample is
    skipped and none is repeated as new):

    - every poll (periodic discrete update, offset 0) appends all that arrived to a FIFO
      and emits its oldest sample, so the chain sees the device's samples in order;
    - **behind** (several samples waiting: the device ran ahead of the simulated clock, or
      the simulation fell behind real time): the backlog is emitted in order, one per
      poll; Drake's real-time pacing runs a lagging simulation faster until it is back on
      the wall clock, which drains the queue. Beyond ``max_backlog`` waiting samples the
      oldest are dropped and counted (``dropped``), bounding the latency;
    - **ahead** (the queue is empty: the device is slower, or stopped): the output holds
      the last sample (never NaN, never a made-up value) and ``underruns`` counts the poll.
      With ``timeout`` set, that many seconds without a sample raise ``EmgDeviceStalled``.

    The queue lives in this object, beside the device it reads: one simulation at a time.
    A sample that is not ``channels`` finite values raises ValueError (nothing non-finite
    reaches the envelope); ``units="int8"`` clips to -128..127, ``units="V"`` keeps values.

    Run the simulator at real-time rate (``Simulator.set_target_realtime_rate(1)``) so
    the polls follow the device's clock.

    Parameters
    ----------
    device : object with ``read_samples()`` or ``read_emg()``
    period : float
        Poll period in s: the device's sample period (MYO: 1/200).
    channels : int
        Values per sample (MYO: 8; e.g. 16 for a 16-electrode armband).
    units : {"int8", "V"}
    max_backlog : int or None
        Samples kept waiting at most; None keeps every one (latency then grows without
        bound if the simulation cannot keep real time).
    timeout : float or None
        Seconds without a new sample after which a poll raises ``EmgDeviceStalled``;
        None (default) holds and counts.
    """

    def __init__(
        self,
        *,
        device,
        period=MYO_PERIOD,
        channels=MYO_CHANNELS,
        units="int8",
        max_backlog=DEFAULT_MAX_BACKLOG,
        timeout=None,
    ):
        self._read = getattr(device, "read_samples", None)
        if not callable(self._read):
            self._read = getattr(device, "read_emg", None)
        if not callable(self._read):
            raise ValueError("device must have a read_samples() or read_emg() method")
        if isinstance(channels, bool) or not isinstance(channels, int) or channels < 1:
            raise ValueError(f"channels must be a positive integer, got {channels!r}")
        if units not in LIVE_UNITS:
            raise ValueError(f"units must be one of {LIVE_UNITS}, got {units!r}")
        if max_backlog is not None and (
            isinstance(max_backlog, bool) or not isinstance(max_backlog, int) or max_backlog < 1
        ):
            raise ValueError(f"max_backlog must be a positive integer or None, got {max_backlog!r}")
        if timeout is not None:
            timeout = as_scalar("timeout", timeout)
        self._device = device
        self._channels = channels
        self._units = units
        self._max_backlog = max_backlog
        self._timeout = timeout
        self._queue = collections.deque()
        self._silent_polls = 0
        _SampledSource.__init__(self, period, channels)
        self._period = float(period)
        self._counter_state = self.DeclareDiscreteState(len(LIVE_COUNTERS))
        self._counters_output = self.DeclareStateOutputPort("counters", self._counter_state)

    def get_counters_output_port(self):
        return self._counters_output

    def counters_dict(self, context):
        """The counters after the last poll, by name (``LIVE_COUNTERS``), as ints."""
        mine = self.GetMyContextFromRoot(context)
        values = mine.get_discrete_state(self._counter_state).get_value()
        return dict(zip(LIVE_COUNTERS, (int(v) for v in values)))

    def status(self, context):
        """One line on the stream's health, for a console or a log."""
        c = self.counters_dict(context)
        return (
            f"sEMG: {c['received']} samples received, {c['emitted']} emitted, "
            f"{c['underruns']} polls with none waiting (device slower or stopped), "
            f"{c['dropped']} dropped (backlog over {self._max_backlog}), "
            f"{c['device_lost']} lost by the device, {c['backlog']} waiting"
        )

    def _block(self, raw):
        """The device's reply as an (n, channels) float array, checked and clipped."""
        block = np.asarray(raw, dtype=float)
        if block.ndim == 1:
            block = block[np.newaxis, :]
        if block.ndim != 2 or block.shape[1] != self._channels or not np.all(np.isfinite(block)):
            raise ValueError(
                f"device.{self._read.__name__}() must return {self._channels} finite values "
                f"per sample, got {raw!r}"
            )
        if self._units == "int8":
            block = np.clip(block, INT8_MIN, INT8_MAX)
        return block

    def _update_sample(self, context, discrete_state):
        k = int(context.get_discrete_state(self._count_state).GetAtIndex(0))
        counters = context.get_discrete_state(self._counter_state).get_value().copy()
        received, emitted, underruns, dropped = (int(v) for v in counters[:4])
        raw = self._read()
        if raw is not None:
            block = self._block(raw)
            self._queue.extend(block)
            received += len(block)
        if self._max_backlog is not None:
            # The poll below takes one; keep at most max_backlog waiting after it.
            while len(self._queue) > self._max_backlog + 1:
                self._queue.popleft()
                dropped += 1
        if self._queue:
            discrete_state.set_value(self._emg_state, self._queue.popleft())
            emitted += 1
            self._silent_polls = 0
        else:
            underruns += 1
            self._silent_polls += 1
            silence = self._silent_polls * self._period
            if self._timeout is not None and silence >= self._timeout - 1e-12:
                raise EmgDeviceStalled(
                    f"no sEMG sample for {silence:.3g} s "
                    f"({self._silent_polls} polls; timeout {self._timeout:g} s): the device "
                    f"stopped or is disconnected ({received} samples received in all)"
                )
        lost = int(getattr(self._device, "lost", 0) or 0)
        discrete_state.set_value(
            self._counter_state,
            [received, emitted, underruns, dropped, len(self._queue), lost],
        )
        discrete_state.set_value(self._count_state, [k + 1])


def open_myo_device(**kwargs):
    """Connect to a MYO armband through ``pyomyo`` (see ``hemg_drake.emg._myo``)."""
    from hemg_drake.emg._myo import open_myo_device as _open

    return _open(**kwargs)
