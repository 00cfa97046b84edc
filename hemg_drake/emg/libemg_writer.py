"""The writer's side of a LibEMG streamer's shared memory, as LibEMG's streamers write it.

:mod:`hemg_drake.emg.libemg` reads that memory; this module writes it the same way
(LibEMG's ``libemg/_streamers`` and ``shared_memory_manager.py``), so a reader can be run
against a stand-in streamer without LibEMG or a device: the tests and benchmarks do, each
in a child process of its own.
"""

from multiprocessing.shared_memory import SharedMemory

import numpy as np

from hemg_drake.emg.libemg import COUNT_DTYPE, EMG_DTYPE


class StreamerMemory:
    """The two blocks a LibEMG streamer creates, zeroed: ``tag`` (the samples, ``rows`` x
    ``channels`` float64, newest first) and ``tag_count`` (int32, 1 x 1, samples written).

    Parameters
    ----------
    tag : str
        The shared-memory name the reader opens.
    rows : int
        The streamer's buffer length (1000 for the MYO).
    channels : int

    Attributes
    ----------
    emg : array, shape (rows, channels); count : array, shape (1, 1)
        Views of the two blocks (None once closed).
    """

    def __init__(self, tag, rows, channels):
        self._blocks = (
            SharedMemory(tag, create=True, size=np.dtype(EMG_DTYPE).itemsize * rows * channels),
            SharedMemory(f"{tag}_count", create=True, size=np.dtype(COUNT_DTYPE).itemsize),
        )
        self.emg = np.ndarray((rows, channels), EMG_DTYPE, buffer=self._blocks[0].buf)
        self.count = np.ndarray((1, 1), COUNT_DTYPE, buffer=self._blocks[1].buf)
        self.emg.fill(0)
        self.count.fill(0)

    def write(self, packet, emg_lock, count_lock):
        """Write one packet as a streamer does: shift the buffer under ``emg_lock``, then,
        in a second critical section under ``count_lock``, add the packet's samples to the
        count (the two locks may be one).

        Parameters
        ----------
        packet : array, shape (n, channels), newest sample first.
        emg_lock, count_lock : multiprocessing.Lock
        """
        with emg_lock:
            self.emg[:] = np.vstack((packet, self.emg))[: len(self.emg)]
        with count_lock:
            self.count[:] = self.count + len(packet)

    def close(self):
        """Drop the views, then close and unlink both blocks (the streamer owns them)."""
        self.emg = self.count = None
        for block in self._blocks:
            block.close()
            block.unlink()
