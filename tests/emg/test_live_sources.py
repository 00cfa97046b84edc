"""Live sEMG: LiveEmgSource's queue policy, and LibEMG's shared memory read by a writer
process that behaves as a LibEMG streamer (same layout, same two critical sections)."""

import multiprocessing
import time
import uuid
from multiprocessing import resource_tracker

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.primitives import LogVectorOutput

from hemg_drake.emg.chain import add_emg_gain_chain
from hemg_drake.emg.libemg import CONFIRM_AFTER, LibEmgSharedMemory
from hemg_drake.emg.libemg_writer import StreamerMemory
from hemg_drake.emg.sources import (
    LIVE_COUNTERS,
    MYO_PERIOD,
    EmgDeviceStalled,
    LiveEmgSource,
)

# ---------------------------------------------------------------- queue policy (fake devices


class ScriptedDevice:
    """Replies, poll after poll, with the scripted blocks (None: nothing arrived)."""

    def __init__(self, replies, lost=0):
        self.replies = list(replies)
        self.lost = lost

    def read_samples(self):
        return self.replies.pop(0) if self.replies else None


def _sample(j, channels=8):
    """Sample number j: channel c holds j + c (distinct, ordered, int8-sized for j < 100)."""
    return [float(j + c) for c in range(channels)]


def _block(first, n, channels=8):
    return np.array([_sample(j, channels) for j in range(first, first + n)])


def _run(builder, simulate, source, n_polls):
    system = builder.AddSystem(source)
    return simulate(
        builder,
        {"emg": system.get_emg_output_port(), "counters": system.get_counters_output_port()},
        n_polls,
    )


def test_every_sample_is_emitted_in_order_when_the_device_runs_ahead(builder, simulate):
    # Device ahead: 3 samples at the first poll, 2 at the fourth, then nothing. The queue
    # emits one per poll in order, then holds the last one and counts underruns.
    device = ScriptedDevice([_block(0, 3), None, None, _block(3, 2)])
    out = _run(builder, simulate, LiveEmgSource(device=device), 8)
    expected = [_sample(j) for j in (0, 1, 2, 3, 4, 4, 4, 4)]
    np.testing.assert_array_equal(out["emg"], expected)
    counters = dict(zip(LIVE_COUNTERS, out["counters"][-1]))
    assert counters == {
        "received": 5, "emitted": 5, "underruns": 3, "dropped": 0, "backlog": 0,
        "device_lost": 0,
    }  # fmt: skip
    # The backlog after each poll, by hand: 2, 1, 0, 1, 0, 0, 0, 0.
    np.testing.assert_array_equal(out["counters"][:, 4], [2, 1, 0, 1, 0, 0, 0, 0])


def test_a_slow_device_holds_its_last_sample_and_counts_underruns(builder, simulate):
    device = ScriptedDevice([None, _sample(0), None, None, _sample(1)], lost=7)
    out = _run(builder, simulate, LiveEmgSource(device=device), 6)
    np.testing.assert_array_equal(
        out["emg"], [[0] * 8, _sample(0), _sample(0), _sample(0), _sample(1), _sample(1)]
    )
    assert not np.any(np.isnan(out["emg"]))
    assert list(out["counters"][-1]) == [2, 2, 4, 0, 0, 7]


def test_backlog_beyond_its_bound_drops_the_oldest(builder, simulate):
    device = ScriptedDevice([_block(0, 10)])
    out = _run(builder, simulate, LiveEmgSource(device=device, max_backlog=3), 5)
    # 10 arrive, one is emitted, 3 may wait: samples 0..5 are dropped, 6..9 come out.
    np.testing.assert_array_equal(out["emg"][:4], [_sample(j) for j in (6, 7, 8, 9)])
    assert list(out["counters"][-1][:5]) == [10, 4, 1, 6, 0]


def test_sixteen_channels_in_volts_are_not_clipped(builder, simulate):
    volts = np.array([[1e-4 * (c + 1) * (-1) ** c for c in range(16)], [300.0] * 16])
    source = LiveEmgSource(device=ScriptedDevice([volts]), channels=16, units="V")
    out = _run(builder, simulate, source, 2)
    np.testing.assert_array_equal(out["emg"], volts)
    with pytest.raises(ValueError, match="16 finite values per sample"):
        simulator = Simulator(
            LiveEmgSource(device=ScriptedDevice([volts[:, :8]]), channels=16, units="V")
        )
        simulator.AdvanceTo(0.01)


def test_myo_default_clips_and_a_nan_never_reaches_the_chain():
    source = LiveEmgSource(device=ScriptedDevice([[[300.0] * 8], [[np.nan] * 8]]))
    simulator = Simulator(source)
    simulator.AdvanceTo(0.001)
    context = simulator.get_context()
    np.testing.assert_array_equal(source.get_emg_output_port().Eval(context), [127.0] * 8)
    with pytest.raises(ValueError, match="8 finite values"):
        simulator.AdvanceTo(0.006)
    assert np.all(np.isfinite(source.get_emg_output_port().Eval(context)))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"channels": 0}, "channels must be a positive integer"),
        ({"units": "mV"}, "units must be one of"),
        ({"max_backlog": 0}, "max_backlog must be a positive integer or None"),
        ({"timeout": -1.0}, "timeout must be finite and > 0"),
    ],
)
def test_bad_parameters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        LiveEmgSource(device=ScriptedDevice([]), **kwargs)


def test_timeout_names_the_silence():
    source = LiveEmgSource(device=ScriptedDevice([_sample(0)]), timeout=0.05)
    simulator = Simulator(source)
    with pytest.raises(EmgDeviceStalled, match=r"no sEMG sample for 0\.05 s \(10 polls"):
        simulator.AdvanceTo(1.0)
    # 1 sample, then 10 silent polls (t = 0.005 .. 0.05) before the raise.
    assert 0.045 <= simulator.get_context().get_time() <= 0.05


# ------------------------------------------------------- a LibEMG streamer in another process

CHANNELS = 8


def _value(j):
    """Sample j of the mimic streamer, row of 8: distinct per sample and per channel."""
    return j + 0.01 * np.arange(CHANNELS)


def _streamer(tag, rows, locks, batches, period, go, written, release):
    """A LibEMG streamer (:class:`~hemg_drake.emg.libemg_writer.StreamerMemory`: ``tag``
    and ``tag_count``, per packet a shift under the buffer's lock, then a count under the
    counter's) writing per phase of ``batches`` its (first sample, number of samples)
    packets."""
    # A real streamer runs under its own resource tracker; this forked child shares the
    # test's, so it leaves the tracker alone and unlinks its memory itself below.
    resource_tracker.register = resource_tracker.unregister = lambda name, rtype: None
    memory = StreamerMemory(tag, rows, CHANNELS)
    try:
        for phase in batches:
            go.wait(10)
            go.clear()
            for first, n in phase:
                packet = np.array([_value(j) for j in range(first + n - 1, first - 1, -1)])
                memory.write(packet, *locks)
                if period:
                    time.sleep(period)
            written.set()
        release.wait(10)
    finally:
        memory.close()


class Streamer:
    """Runs ``_streamer`` in a child process; ``phase()`` lets it write the next phase."""

    def __init__(self, phases, *, rows=1000, period=0.0, shared_lock=True):
        context = multiprocessing.get_context("fork")
        self.tag = f"hemg_test_{uuid.uuid4().hex[:12]}"
        emg_lock = context.Lock()
        self.locks = (emg_lock, emg_lock if shared_lock else context.Lock())
        self.go, self.written, self.release = context.Event(), context.Event(), context.Event()
        self.process = context.Process(
            target=_streamer,
            args=(self.tag, rows, self.locks, phases, period, self.go, self.written,
                  self.release),
            daemon=True,
        )  # fmt: skip
        self.process.start()

    def phase(self, *, wait=True):
        self.written.clear()
        self.go.set()
        if wait:
            assert self.written.wait(10), "the mimic streamer did not finish its phase"

    def stop(self):
        self.release.set()
        self.process.join(10)


@pytest.fixture
def streamers():
    started = []

    def start(*args, **kwargs):
        streamer = Streamer(*args, **kwargs)
        started.append(streamer)
        return streamer

    yield start
    for streamer in started:
        streamer.stop()


def _packets(first, total, size):
    return [(j, min(size, first + total - j)) for j in range(first, first + total, size)]


def _drain(reader):
    """What a reader returns for an idle streamer: read until nothing more comes (without
    the locks, a snapshot is emitted when the next read confirms it)."""
    blocks, last = [], time.monotonic()
    while time.monotonic() - last < CONFIRM_AFTER + 0.01:  # the confirmation, then 10 ms more
        block = reader.read_samples()
        if block is not None:
            blocks, last = blocks + [block], time.monotonic()
        time.sleep(0.001)
    return np.concatenate(blocks) if blocks else None


def _read_until(reader, n_expected, timeout=10.0):
    blocks, deadline = [], time.monotonic() + timeout
    got = 0
    while got < n_expected and time.monotonic() < deadline:
        block = reader.read_samples()
        if block is not None:
            blocks.append(block)
            got += len(block)
        else:
            time.sleep(0.0005)
    return np.concatenate(blocks) if blocks else np.zeros((0, CHANNELS))


@pytest.mark.parametrize("with_locks, shared_lock", [(True, True), (True, False), (False, True)])
def test_reader_gets_every_sample_in_order_while_the_streamer_writes(
    streamers, with_locks, shared_lock
):
    # MYO-like packets of 2 samples, written while the reader polls at its own pace.
    streamer = streamers([[], _packets(0, 600, 2)], rows=100, period=0.0002,
                         shared_lock=shared_lock)  # fmt: skip
    streamer.phase()  # the memory exists, nothing written yet
    locks = dict(zip(("lock", "count_lock"), streamer.locks)) if with_locks else {}
    with LibEmgSharedMemory(channels=CHANNELS, tag=streamer.tag, **locks) as reader:
        streamer.phase(wait=False)
        samples = _read_until(reader, 600)
        assert streamer.written.wait(10)
        assert _drain(reader) is None
        np.testing.assert_array_equal(samples, [_value(j) for j in range(600)])
        assert reader.lost == 0 and reader.resets == 0


def test_a_late_reader_starts_from_now_or_from_the_buffer(streamers):
    streamer = streamers([_packets(0, 300, 2), _packets(300, 50, 5)], rows=120)
    streamer.phase()  # 300 samples before anyone reads
    now = LibEmgSharedMemory(channels=CHANNELS, tag=streamer.tag)
    held = LibEmgSharedMemory(channels=CHANNELS, tag=streamer.tag, start="buffer")
    assert _drain(now) is None
    # The ring holds the newest 120 of the first 300: samples 180..299.
    np.testing.assert_array_equal(_drain(held), [_value(j) for j in range(180, 300)])
    streamer.phase()
    np.testing.assert_array_equal(_drain(now), [_value(j) for j in range(300, 350)])
    np.testing.assert_array_equal(_drain(held), [_value(j) for j in range(300, 350)])
    assert now.lost == 0 and held.lost == 0
    now.close()
    held.close()


def test_a_streamer_faster_than_the_reader_overwrites_and_is_counted(streamers):
    streamer = streamers([_packets(0, 10, 2), _packets(10, 500, 4), _packets(510, 6, 3)],
                         rows=64)  # fmt: skip
    streamer.phase()
    with LibEmgSharedMemory(channels=CHANNELS, tag=streamer.tag) as reader:
        streamer.phase()  # 500 samples while the reader sleeps: the ring keeps 64
        np.testing.assert_array_equal(_drain(reader), [_value(j) for j in range(446, 510)])
        assert reader.lost == 500 - 64
        streamer.phase()
        np.testing.assert_array_equal(_drain(reader), [_value(j) for j in range(510, 516)])


def test_a_stopped_streamer_leaves_the_source_holding_with_counters(streamers):
    streamer = streamers([[], _packets(0, 12, 2)], rows=100)
    streamer.phase()
    reader = LibEmgSharedMemory(channels=CHANNELS, tag=streamer.tag)
    source = LiveEmgSource(device=reader)
    simulator = Simulator(source)
    # Real time, as with a device: a lock-free read is confirmed by the next poll, 5 ms on.
    simulator.set_target_realtime_rate(1.0)
    simulator.AdvanceTo(0.0201)  # 5 polls with nothing yet
    streamer.phase()  # 12 samples, then the streamer stops writing
    simulator.AdvanceTo(0.2)  # 40 polls in all
    context = simulator.get_context()
    counters = source.counters_dict(context)
    assert counters == {
        "received": 12, "emitted": 12, "underruns": 28, "dropped": 0, "backlog": 0,
        "device_lost": 0,
    }  # fmt: skip
    np.testing.assert_array_equal(source.get_emg_output_port().Eval(context), _value(11))
    assert "12 samples received, 12 emitted, 28 polls with none waiting" in source.status(context)
    reader.close()
    # With a timeout, the silence is named; what was read came out in order first.
    late = LibEmgSharedMemory(channels=CHANNELS, tag=streamer.tag, start="buffer")
    strict = LiveEmgSource(device=late, timeout=0.05)
    simulator = Simulator(strict)
    simulator.set_target_realtime_rate(1.0)
    with pytest.raises(EmgDeviceStalled, match=r"0\.05 s .*12 samples received in all"):
        simulator.AdvanceTo(1.0)
    np.testing.assert_array_equal(
        strict.get_emg_output_port().Eval(simulator.get_context()), _value(11)
    )
    late.close()


def test_lock_free_reads_against_a_streamer_flat_out_are_never_torn_or_doubled(streamers):
    # No locks at the reader (a LibEMG in another environment), a writer without pauses:
    # whatever is read is whole samples, in order, none twice; the rest is counted lost.
    total = 20000
    streamer = streamers([[], _packets(0, total, 2)], rows=1000)
    streamer.phase()
    with LibEmgSharedMemory(channels=CHANNELS, tag=streamer.tag) as reader:
        streamer.phase(wait=False)
        blocks = []
        while not streamer.written.is_set():
            block = reader.read_samples()
            if block is not None:
                blocks.append(block)
        rest = _drain(reader)
        samples = np.concatenate(blocks + ([] if rest is None else [rest]))
        index = samples[:, 0]
        np.testing.assert_array_equal(samples, [_value(j) for j in index.astype(int)])
        assert np.all(np.diff(index) >= 1) and index[-1] == total - 1
        assert len(samples) + reader.lost == total


def test_a_missing_streamer_and_a_wrong_channel_count_are_named(streamers):
    with pytest.raises(FileNotFoundError, match="no LibEMG shared memory 'hemg_absent'.*streamer"):
        LibEmgSharedMemory(channels=8, tag="hemg_absent", wait=0.05)
    streamer = streamers([[]], rows=10)
    streamer.phase()
    with pytest.raises(ValueError, match="640 bytes, not a whole number of 7-channel"):
        LibEmgSharedMemory(channels=7, tag=streamer.tag)


def test_live_source_feeds_the_gain_chain_unchanged(builder):
    # Blocks of 2 (as the MYO delivers them), one poll each, then one poll with none.
    rng = np.random.default_rng(4)
    samples = rng.integers(-128, 128, (60, 8)).astype(float)
    replies = []
    for k in range(0, 60, 2):
        replies += [samples[k:k + 2], None]
    source = builder.AddSystem(LiveEmgSource(device=ScriptedDevice(replies)))
    rms, _ = add_emg_gain_chain(builder, source.get_emg_output_port())
    log = LogVectorOutput(rms.get_envelope_output_port(), builder, publish_period=MYO_PERIOD)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(60 * MYO_PERIOD)
    envelope = log.FindLog(simulator.get_context()).data()[0, 1:]
    # Eqs. 1-2 by hand: RMS over the last 20 samples of the channel sum, zeros before.
    sums = np.concatenate([np.zeros(19), samples.sum(axis=1)])
    expected = [np.sqrt(np.mean(sums[k:k + 20] ** 2)) for k in range(60)]
    np.testing.assert_allclose(envelope, expected, rtol=1e-12)


def test_myo_reader_queues_every_sample_and_counts_what_it_drops():
    from hemg_drake.emg._myo import PyomyoDevice

    class PairedMyo:
        """pyomyo's raw mode: each BLE notification calls the handler twice, in order."""

        def __init__(self, n_pairs):
            self.handlers, self.sent, self.n_pairs = [], 0, n_pairs

        def add_emg_handler(self, handler):
            self.handlers.append(handler)

        def run(self):
            if self.sent < 2 * self.n_pairs:
                for j in (self.sent, self.sent + 1):
                    for handler in self.handlers:
                        handler(tuple(int(v) for v in _sample(j)), 0)
                self.sent += 2
            else:
                time.sleep(0.001)

        def disconnect(self):
            pass

    device = PyomyoDevice(PairedMyo(30))
    try:
        samples = _read_until(device, 60)
        np.testing.assert_array_equal(samples, [_sample(j) for j in range(60)])
        assert device.lost == 0
    finally:
        device.close()
    small = PyomyoDevice(PairedMyo(30), max_pending=10)
    try:
        deadline = time.monotonic() + 5
        while small.lost < 50 and time.monotonic() < deadline:
            time.sleep(0.001)
        np.testing.assert_array_equal(small.read_samples(), [_sample(j) for j in range(50, 60)])
        assert small.lost == 50
    finally:
        small.close()


def test_libemg_source_in_one_call(streamers):
    from hemg_drake.emg.libemg import libemg_emg_source

    streamer = streamers([[], _packets(0, 4, 2)], rows=50)
    streamer.phase()
    source, reader = libemg_emg_source(tag=streamer.tag, lock=streamer.locks[0],
                                       count_lock=streamer.locks[1])  # fmt: skip
    streamer.phase()
    simulator = Simulator(source)
    simulator.AdvanceTo(0.0151)  # polls at 0, 5, 10, 15 ms: the four samples in order
    np.testing.assert_array_equal(source.get_emg_output_port().Eval(simulator.get_context()),
                                  _value(3))  # fmt: skip
    assert source.counters_dict(simulator.get_context())["emitted"] == 4
    reader.close()
    with pytest.raises(ValueError, match="units must be one of"):
        libemg_emg_source(tag=streamer.tag, units="mV")
