"""Any armband LibEMG streams, read straight from its shared memory (LibEMG not imported).

LibEMG (LibEMG/libemg) drives the common sEMG devices (MYO, Delsys, OYMotion, SiFi, ...)
with one streamer process each. A streamer publishes into POSIX shared memory, which
LibEMG's ``OnlineDataHandler`` reads; LibEMG pins ``numpy<2``, which Drake's wheels do not
allow, so it runs in its own environment and this module reads the same memory by name:

- ``emg``: float64, shape (rows, channels), **newest sample first**: each write does
  ``emg[:] = vstack((new_samples_newest_first, emg))[:rows]`` (``rows`` is the
  streamer's buffer length, e.g. 1000 for the MYO, 3000 for a Delsys);
- ``emg_count``: int32, shape (1, 1), samples written since the streamer started (or
  since ``OnlineDataHandler.reset()``, which zeroes both);
- locks: ``multiprocessing.Lock`` objects, one per variable (a newer LibEMG shares one
  between ``emg`` and ``emg_count``). The writer shifts ``emg`` under its lock and then
  increments ``emg_count`` in a second critical section. Such locks cannot be opened by
  name: a reader in another process tree has none, and gets them only when it shares a
  parent with the streamer (pass ``lock``/``count_lock``).

So the pair can be seen half-updated: a buffer already shifted and a count not yet
incremented, or (without the lock) a buffer copied mid-shift. ``read_samples`` takes a
snapshot it can check: the count before and after two copies of the rows it needs must
agree, the copies must be equal, and the row just past the new ones must be the newest
sample of the previous read (the buffer is a shift register). A snapshot that fails is
retried a few times and otherwise left for the next poll. Without the locks, a streamer
preempted in the middle of its copy leaves a torn buffer that can pass those checks, so a
lock-free snapshot is emitted only once a later one confirms it (one poll of latency).
Guarantee, tested against a writer that never pauses: the samples come whole, in order,
none twice, and ``len(all returned) + lost`` is the number written.
"""

import contextlib
import time
from multiprocessing.shared_memory import SharedMemory

import numpy as np

EMG_DTYPE = np.float64
COUNT_DTYPE = np.int32
# Attempts at a consistent snapshot per poll, and the pause between them (the writer's
# two critical sections are microseconds apart).
SNAPSHOT_ATTEMPTS = 5
SNAPSHOT_PAUSE = 50e-6
# Wait before trusting a snapshot that cannot be aligned with the previous read.
SETTLE_PAUSE = 200e-6
# Samples an unaligned read may have taken early at most (a streamer's packet).
MAX_CATCH_UP = 64
# Lock-free reading: an unchanged snapshot confirms a pending one only this much later
# (a streamer preempted in the middle of its copy rarely stays so that long; at 2 ms a
# loaded 2-core machine let a torn row through in about 1 run of 10).
CONFIRM_AFTER = 30e-3
# Reads in a row without a consistent snapshot before the alignment is given up.
RESYNC_AFTER = 20
_INSTALL_HINT = "start the LibEMG streamer first (docs/emg.md, 'Live sources')"


def _attach(name):
    """Open an existing shared-memory block without making this process its owner."""
    try:
        return SharedMemory(name=name, create=False, track=False)  # Python >= 3.13
    except TypeError:
        pass
    # Python < 3.13 registers every opened block with the resource tracker, which unlinks
    # it when this process exits: the streamer's memory would vanish under it.
    from multiprocessing import resource_tracker

    block = SharedMemory(name=name, create=False)
    resource_tracker.unregister(block._name, "shared_memory")
    return block


class LibEmgSharedMemory:
    """A device for ``LiveEmgSource``: the samples a LibEMG streamer wrote, in order.

    Parameters
    ----------
    channels : int
        Columns of the ``emg`` buffer (MYO: 8; a Delsys Trigno: one per sensor).
    tag : str
        Name of the buffer; the counter is ``tag + "_count"`` (LibEMG: ``"emg"``).
    lock, count_lock : multiprocessing lock, optional
        The streamer's locks of ``emg`` and ``emg_count`` (from LibEMG's
        ``shared_memory_items``), when this process can have them; either may be the
        same object. Without them the snapshot checks alone keep reads consistent.
    start : {"now", "buffer"}
        "now": the first read returns what arrives after opening (a late reader does not
        replay stale seconds); "buffer": it returns what the buffer still holds too.
    wait : float
        Seconds to wait for the streamer to create the memory.

    Attributes
    ----------
    lost : int
        Samples overwritten in the ring before they were read (the reader was too slow).
    resets : int
        Times the counter went back (``OnlineDataHandler.reset()``, a restarted streamer).
    retries : int
        Snapshots found inconsistent and taken again (a write was in progress).
    realigned : int
        Reads that found an earlier unaligned read had taken samples not yet counted
        (after a reset or a loss, with a writer preempted between its two steps).
    resyncs : int
        Times the alignment with the previous read was given up after ``RESYNC_AFTER``
        reads in a row without a consistent snapshot.
    """

    def __init__(self, *, channels, tag="emg", lock=None, count_lock=None, start="now", wait=5.0):
        if isinstance(channels, bool) or not isinstance(channels, int) or channels < 1:
            raise ValueError(f"channels must be a positive integer, got {channels!r}")
        if start not in ("now", "buffer"):
            raise ValueError(f"start must be 'now' or 'buffer', got {start!r}")
        self.tag, self.count_tag = tag, f"{tag}_count"
        self._emg_block = self._count_block = None
        deadline = time.monotonic() + float(wait)
        while True:
            try:
                self._emg_block = _attach(self.tag)
                self._count_block = _attach(self.count_tag)
                break
            except FileNotFoundError:
                self._close_blocks()
                if time.monotonic() >= deadline:
                    raise FileNotFoundError(
                        f"no LibEMG shared memory {self.tag!r}/{self.count_tag!r} after "
                        f"{float(wait):g} s: {_INSTALL_HINT}"
                    ) from None
                time.sleep(0.05)
        row_bytes = channels * np.dtype(EMG_DTYPE).itemsize
        if self._emg_block.size % row_bytes or self._emg_block.size < row_bytes:
            size = self._emg_block.size
            self._close_blocks()
            raise ValueError(
                f"shared memory {self.tag!r} holds {size} bytes, not a whole number of "
                f"{channels}-channel float64 rows: check channels"
            )
        self.rows = self._emg_block.size // row_bytes
        self.channels = channels
        self._emg = np.ndarray((self.rows, channels), EMG_DTYPE, buffer=self._emg_block.buf)
        self._count = np.ndarray((1, 1), COUNT_DTYPE, buffer=self._count_block.buf)
        # Distinct locks, taken in one fixed order (as LibEMG's reader does).
        given = {id(lk): lk for lk in (lock, count_lock) if lk is not None}
        self._locks = [given[key] for key in sorted(given)]
        self.lost = self.resets = self.retries = self.realigned = self.resyncs = 0
        self._pending = None  # lock-free reading: the snapshot awaiting confirmation
        self._failures = 0  # reads in a row without a consistent snapshot
        count = int(self._count[0, 0])
        self._last = count if start == "now" else max(count - self.rows, 0)
        # The row just past the unread ones: the newest read sample, or one of the zeros
        # the streamer filled the buffer with; unknown if that row was overwritten.
        behind = count - self._last
        self._newest = self._emg[behind].copy() if behind < self.rows else None

    @contextlib.contextmanager
    def _locked(self):
        with contextlib.ExitStack() as stack:
            for lk in self._locks:
                stack.enter_context(lk)
            yield

    def _snapshot(self):
        """(count, rows newest first) if consistent, else None; rows empty when none new.

        The rows are samples count - len(rows) .. count - 1.
        """
        with self._locked():
            count = int(self._count[0, 0])
            new = count - self._last
            if new <= 0:
                return count, self._emg[:0].copy()
            # One row past the new ones to check the alignment, when the ring holds it.
            needed = min(new + 1, self.rows)
            first = self._emg[:needed].copy()
            second = self._emg[:needed].copy()
            unchanged = int(self._count[0, 0]) == count
        if not (unchanged and np.array_equal(first, second)):
            return None
        if self._newest is None or new >= self.rows:
            # Nothing to align with (samples lost, or a late start after a full ring): let a write
            # caught between its two critical sections finish, then check nothing moved.
            time.sleep(SETTLE_PAUSE)
            with self._locked():
                moved = int(self._count[0, 0]) != count or not np.array_equal(
                    self._emg[0], first[0]
                )
            return None if moved else (count, first[: min(new, self.rows)])
        if np.array_equal(first[new], self._newest):
            return count, first[:new]
        # An unaligned read may still have taken k samples shifted in but not yet counted
        # (the writer paused between its two steps): the previous newest is then k rows
        # nearer the top, and those k were emitted then (and as many of the oldest missed,
        # which ``_emit`` counts as lost: these rows start k samples late).
        for k in range(1, min(new, MAX_CATCH_UP) + 1):
            if np.array_equal(first[new - k], self._newest):
                self.realigned += 1
                return count, first[: new - k]
        return None  # shifted, not yet counted (or torn): the write is in progress

    def read_samples(self):
        """Every sample written since the last call, shape (n, channels), oldest first.

        None when nothing new arrived, or when no consistent snapshot could be had this
        time (those samples come with a later call). Without the streamer's locks a
        snapshot is emitted only once a later one confirms it (next section).
        """
        count = int(self._count[0, 0])
        if count < self._last:  # zeroed by OnlineDataHandler.reset() or a new streamer
            self.resets += 1
            self._last, self._newest, self._pending = 0, np.zeros(self.channels), None
        for attempt in range(SNAPSHOT_ATTEMPTS):
            snapshot = self._snapshot()
            if snapshot is not None:
                break
            self.retries += 1
            time.sleep(SNAPSHOT_PAUSE)
        else:
            self._failures += 1
            if self._failures >= RESYNC_AFTER:
                # The previous newest sample is nowhere to be found (say, a row torn in
                # the middle was taken for it): align on the count alone from now on.
                self._newest, self._failures = None, 0
                self.resyncs += 1
            return None
        self._failures = 0
        count, rows = snapshot
        if not self._locks:
            count, rows = self._confirmed(count, rows)
        if rows is None or len(rows) == 0:
            return None
        self.lost += max(0, count - len(rows) - self._last)
        self._last, self._newest = count, rows[0].copy()
        return rows[::-1].copy()

    def _confirmed(self, count, rows):
        """Lock-free reading: the rows of the pending snapshot that this one confirms.

        Without the locks, a streamer preempted in the middle of its copy leaves a torn
        buffer (its top rows shifted, the rest not), which may look consistent for as
        long as it is preempted. So a snapshot waits: it is emitted once a later one shows
        the same rows where they must be, either unchanged (count unchanged: the streamer
        is idle) or moved down by exactly the samples counted since. Costs one poll of
        latency (MYO through LibEMG: 5 ms at most).

        Returns (count, rows) to emit, or (count, None).
        """
        now = time.monotonic()
        pending, self._pending = self._pending, ((count, rows, now) if len(rows) else None)
        if pending is None or not len(rows):
            return count, None
        pending_count, pending_rows, taken = pending
        offset = count - pending_count
        if offset == 0:
            if not np.array_equal(rows, pending_rows):
                return count, None
            if now - taken < CONFIRM_AFTER:
                self._pending = pending  # too soon to tell an idle streamer from a stalled copy
                return count, None
            self._pending = None
            return pending_count, pending_rows
        # The pending rows that this snapshot still holds (all, unless the ring moved on).
        common = min(len(pending_rows), len(rows) - offset)
        if offset > 0 and common > 0 and np.array_equal(
            rows[offset : offset + common], pending_rows[:common]
        ):
            self._pending = (count, rows[:offset], now)
            return pending_count, pending_rows[:common]
        return count, None

    def _close_blocks(self):
        for block in (self._emg_block, self._count_block):
            if block is not None:
                block.close()
        self._emg_block = self._count_block = None

    def close(self):
        """Stop reading; the streamer keeps (and later unlinks) its memory."""
        self._emg = self._count = None
        self._close_blocks()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def libemg_emg_source(*, channels=8, units="int8", period=None, tag="emg", timeout=None,
                      wait=5.0, **reader_options):
    """A ``LiveEmgSource`` reading a LibEMG streamer's shared memory, and its reader.

    The defaults fit LibEMG's ``myo_streamer(filtered=False)``: 8 int8 channels at
    200 Hz. Close the reader (``reader.close()``) when the simulation is over.

    Returns
    -------
    source : LiveEmgSource
    reader : LibEmgSharedMemory
    """
    from hemg_drake.emg.live import LiveEmgSource
    from hemg_drake.emg.config import MYO_PERIOD

    reader = LibEmgSharedMemory(channels=channels, tag=tag, wait=wait, **reader_options)
    try:
        source = LiveEmgSource(
            device=reader, channels=channels, units=units,
            period=MYO_PERIOD if period is None else period, timeout=timeout,
        )  # fmt: skip
    except ValueError:
        reader.close()
        raise
    return source, reader
