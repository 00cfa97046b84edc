"""A live armband as a Drake source: every sample the device delivered, in order."""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake._validate import as_scalar
from hemg_drake.emg.config import INT8_MAX, INT8_MIN, MYO_CHANNELS, MYO_PERIOD

# Units of a live device's samples: how they are checked and clipped.
# "int8": the MYO's raw ADC counts, clipped to -128..127 (a driver may hand out wider ints);
# "V": volts, as LibEMG's streamers of Delsys, SiFi or OYMotion armbands give them, unclipped.
LIVE_UNITS = ("int8", "V")
# Samples kept waiting at most (1 s at 200 Hz) before the oldest are dropped: a backlog that
# long means the simulation runs persistently slower than real time.
DEFAULT_MAX_BACKLOG = 200
# The counters a LiveEmgSource keeps, in the order of its ``counters`` output port, then the
# polls in a row without a sample (for the timeout).
LIVE_COUNTERS = ("received", "emitted", "underruns", "dropped", "backlog", "device_lost")


class EmgDeviceStalled(RuntimeError):
    """A live sEMG device delivered nothing for longer than the source's ``timeout``."""


def _reader(device):
    read = getattr(device, "read_samples", None)
    if not callable(read):
        read = getattr(device, "read_emg", None)
    if not callable(read):
        raise ValueError("device must have a read_samples() or read_emg() method")
    return read


@TemplateSystem.define("LiveEmgSource_", T_list=(float, AutoDiffXd))
def LiveEmgSource_(T):
    class Impl(LeafSystem_[T]):
        """Emits every raw sEMG sample a live armband delivered, in order, one per period.

        .. pydrake_system::

            name: LiveEmgSource
            output_ports:
            - emg
            - counters

        ``emg`` (``channels``; MYO units by default, or volts): the next sample of the queue
        at each poll, held between polls, zero before the first. ``counters`` (6): the totals
        of ``LIVE_COUNTERS`` after the last poll (``counters_dict`` names them).

        The device is any object with ``read_samples()`` (preferred) or ``read_emg()``,
        returning None when nothing arrived, one sample (shape (channels,)) or every sample
        since the last call (shape (n, channels), oldest first). ``open_myo_device()`` gives
        one for a MYO, ``hemg_drake.emg.libemg.LibEmgSharedMemory`` one for any armband that
        a LibEMG streamer publishes; an optional attribute ``lost`` (samples the device
        itself lost) is reported too.

        Queue policy (the device's clock and the simulator's drift apart; no sample is
        skipped and none is repeated as new):

        - every poll (periodic unrestricted update, offset 0) appends all that arrived to a
          FIFO and emits its oldest sample, so the chain sees the device's samples in order;
        - **behind** (several samples waiting): the backlog is emitted in order, one per
          poll; Drake's real-time pacing runs a lagging simulation faster until it is back
          on the wall clock. Beyond ``max_backlog`` waiting samples the oldest are dropped
          and counted (``dropped``), bounding the latency;
        - **ahead** (the queue is empty): the output holds the last sample (never NaN, never
          a made-up value) and ``underruns`` counts the poll. With ``timeout`` set, that
          many seconds without a sample raise ``EmgDeviceStalled``.

        State, all in the Context: the FIFO (abstract state, an (n, channels) array
        replaced at each poll), the emitted sample and the counters (discrete state). The
        device itself is outside Drake: it hands each sample out once, so of two contexts
        (or a Clone) polling one device, each sees part of the stream; run one at a time.
        Converted to AutoDiffXd (a Clone needs a conversion), the samples carry no
        derivatives. A sample that is not ``channels`` finite values raises ValueError;
        ``units="int8"`` clips to -128..127, ``units="V"`` keeps values. Run the simulator
        at real-time rate (``Simulator.set_target_realtime_rate(1)``).

        Parameters
        ----------
        device : object with ``read_samples()`` or ``read_emg()``
        period : float
            Poll period in s: the device's sample period (MYO: 1/200).
        channels : int
            Values per sample (MYO: 8; e.g. 16 for a 16-electrode armband).
        units : {"int8", "V"}
        max_backlog : int or None
            Samples kept waiting at most; None keeps every one.
        timeout : float or None
            Seconds without a new sample after which a poll raises ``EmgDeviceStalled``;
            None holds and counts.
        """

        def _construct(self, *, device, period=MYO_PERIOD, channels=MYO_CHANNELS, units="int8",
                       max_backlog=DEFAULT_MAX_BACKLOG, timeout=None, converter=None):  # fmt: skip
            LeafSystem_[T].__init__(self, converter)
            self._read = _reader(device)
            if isinstance(channels, bool) or not isinstance(channels, int) or channels < 1:
                raise ValueError(f"channels must be a positive integer, got {channels!r}")
            if units not in LIVE_UNITS:
                raise ValueError(f"units must be one of {LIVE_UNITS}, got {units!r}")
            if max_backlog is not None and (
                isinstance(max_backlog, bool) or not isinstance(max_backlog, int) or max_backlog < 1
            ):
                raise ValueError(
                    f"max_backlog must be a positive integer or None, got {max_backlog!r}"
                )
            if timeout is not None:
                timeout = as_scalar("timeout", timeout)
            self._device, self._channels, self._units = device, channels, units
            self._max_backlog, self._timeout = max_backlog, timeout
            self._period = as_scalar("period", period)
            self._queue_state = self.DeclareAbstractState(
                AbstractValue.Make(np.zeros((0, channels)))
            )
            self._emg_state = self.DeclareDiscreteState(channels)
            # LIVE_COUNTERS, then the polls in a row without a sample.
            self._counter_state = self.DeclareDiscreteState(len(LIVE_COUNTERS) + 1)
            self.DeclarePeriodicUnrestrictedUpdateEvent(self._period, 0.0, self._poll)
            self._emg_output = self.DeclareStateOutputPort("emg", self._emg_state)
            self._counters_output = self.DeclareVectorOutputPort(
                "counters", len(LIVE_COUNTERS), self._calc_counters,
                prerequisites_of_calc={self.discrete_state_ticket(self._counter_state)},
            )  # fmt: skip

        def _construct_copy(self, other, converter=None):
            Impl._construct(
                self, device=other._device, period=other._period, channels=other._channels,
                units=other._units, max_backlog=other._max_backlog, timeout=other._timeout,
                converter=converter,
            )  # fmt: skip

        def get_emg_output_port(self):
            return self._emg_output

        def get_counters_output_port(self):
            return self._counters_output

        def counters_dict(self, context):
            """The counters after the last poll, by name (``LIVE_COUNTERS``), as ints."""
            mine = self.GetMyContextFromRoot(context)
            values = mine.get_discrete_state(self._counter_state).CopyToVector()
            return dict(zip(LIVE_COUNTERS, (int(_float(v)) for v in values)))

        def status(self, context):
            """One line on the stream's health, for a console or a log."""
            c = self.counters_dict(context)
            return (
                f"sEMG: {c['received']} samples received, {c['emitted']} emitted, "
                f"{c['underruns']} polls with none waiting (device slower or stopped), "
                f"{c['dropped']} dropped (backlog over {self._max_backlog}), "
                f"{c['device_lost']} lost by the device, {c['backlog']} waiting"
            )

        def _calc_counters(self, context, output):
            values = context.get_discrete_state(self._counter_state).CopyToVector()
            output.SetFromVector(values[: len(LIVE_COUNTERS)])

        def _block(self, raw):
            """The device's reply as an (n, channels) float array, checked and clipped."""
            block = np.asarray(raw, dtype=float)
            if block.ndim == 1:
                block = block[np.newaxis, :]
            if block.ndim != 2 or block.shape[1] != self._channels or not np.all(np.isfinite(block)):
                raise ValueError(
                    f"device.{self._read.__name__}() must return {self._channels} finite "
                    f"values per sample, got {raw!r}"
                )
            if self._units == "int8":
                block = np.clip(block, INT8_MIN, INT8_MAX)
            return block

        def _poll(self, context, state):
            counters = [int(_float(v)) for v in
                        context.get_discrete_state(self._counter_state).CopyToVector()]  # fmt: skip
            received, emitted, underruns, dropped, _, _, silent = counters
            queue = context.get_abstract_state(int(self._queue_state)).get_value()
            raw = self._read()
            if raw is not None:
                block = self._block(raw)
                queue = np.concatenate([queue, block])
                received += len(block)
            if self._max_backlog is not None and len(queue) > self._max_backlog + 1:
                # The poll below takes one; keep at most max_backlog waiting after it.
                dropped += len(queue) - (self._max_backlog + 1)
                queue = queue[len(queue) - (self._max_backlog + 1) :]
            if len(queue):
                state.get_mutable_discrete_state(self._emg_state).SetFromVector(queue[0])
                queue = queue[1:]
                emitted += 1
                silent = 0
            else:
                underruns += 1
                silent += 1
                silence = silent * self._period
                if self._timeout is not None and silence >= self._timeout - 1e-12:
                    raise EmgDeviceStalled(
                        f"no sEMG sample for {silence:.3g} s ({silent} polls; timeout "
                        f"{self._timeout:g} s): the device stopped or is disconnected "
                        f"({received} samples received in all)"
                    )
            state.get_mutable_abstract_state(int(self._queue_state)).set_value(queue.copy())
            lost = int(getattr(self._device, "lost", 0) or 0)
            state.get_mutable_discrete_state(self._counter_state).SetFromVector(
                [received, emitted, underruns, dropped, len(queue), lost, silent]
            )

    return Impl


def _float(x):
    return x.value() if isinstance(x, AutoDiffXd) else float(x)


LiveEmgSource = LiveEmgSource_[None]


def open_myo_device(**kwargs):
    """Connect to a MYO armband through ``pyomyo`` (see ``hemg_drake.emg._myo``)."""
    from hemg_drake.emg._myo import open_myo_device as _open

    return _open(**kwargs)
