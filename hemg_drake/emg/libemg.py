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
retried a few times and otherwise left for the next poll, so nothing is lost or doubled.
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
        self.lost = self.resets = self.retries = 0
        count = int(self._count[0, 0])
        held = min(count, self.rows)
        self._last = count if start == "now" else count - held
        self._newest = self._emg[0].copy() if start == "now" and count > 0 else None

    @contextlib.contextmanager
    def _locked(self):
        with contextlib.ExitStack() as stack:
            for lk in self._locks:
                stack.enter_context(lk)
            yield

    def _snapshot(self):
        """(count, rows newest first) if consistent, else None; rows empty when none new."""
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
        if new < self.rows and self._newest is not None and not np.array_equal(
            first[new], self._newest
        ):
            return None  # shifted, not yet counted (or torn): the write is in progress
        return count, first[: min(new, self.rows)]

    def read_samples(self):
        """Every sample written since the last call, shape (n, channels), oldest first.

        None when nothing new arrived, or when no consistent snapshot could be had this
        time (those samples come with the next call).
        """
        count = int(self._count[0, 0])
        if count < self._last:  # zeroed by OnlineDataHandler.reset() or a new streamer
            self.resets += 1
            self._last, self._newest = 0, None
        for attempt in range(SNAPSHOT_ATTEMPTS):
            snapshot = self._snapshot()
            if snapshot is not None:
                break
            self.retries += 1
            time.sleep(SNAPSHOT_PAUSE)
        else:
            return None
        count, rows = snapshot
        if len(rows) == 0:
            return None
        self.lost += max(0, count - self._last - self.rows)
        self._last, self._newest = count, rows[0].copy()
        return rows[::-1].copy()

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
