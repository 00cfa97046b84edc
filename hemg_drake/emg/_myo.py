"""Live MYO armband through the optional ``pyomyo`` driver (extra ``hemg-drake[myo]``).

All device access lives here; ``LiveEmgSource`` only calls ``read_samples()``, so
it is tested with a fake device and this module with a fake ``pyomyo``.
"""

import collections
import threading

import numpy as np

_INSTALL_HINT = "install the optional extra: pip install 'hemg-drake[myo]'"


def _import_pyomyo():
    try:
        import pyomyo
    except ImportError as error:
        raise ModuleNotFoundError(
            f"the live MYO source needs the pyomyo package ({_INSTALL_HINT})"
        ) from error
    return pyomyo


# Samples the reader thread keeps for LiveEmgSource at most (10 s at 200 Hz); older ones
# are counted in ``lost``: a simulation that stalls that long has lost the stream anyway.
MAX_PENDING = 2000


class PyomyoDevice:
    """A connected MYO streaming raw sEMG, read by a background thread.

    pyomyo delivers samples through a handler called from ``Myo.run()``; a daemon thread
    keeps calling it and the handler queues every sample, oldest first, which
    ``read_samples()`` hands out (``LiveEmgSource`` emits each one, in order).

    Parameters
    ----------
    myo : pyomyo.Myo
        Already connected, in raw EMG mode.
    max_pending : int
        Samples kept waiting at most; beyond that the oldest are dropped and counted in
        ``lost``.
    """

    def __init__(self, myo, *, max_pending=MAX_PENDING):
        self._myo = myo
        self._lock = threading.Lock()
        self._pending = collections.deque()
        self._max_pending = int(max_pending)
        self.lost = 0
        self._running = True
        myo.add_emg_handler(self._on_emg)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _on_emg(self, emg, movement=None):
        rows = np.asarray(emg, dtype=float)
        rows = rows[np.newaxis, :8] if rows.ndim == 1 else rows[:, :8]
        with self._lock:
            self._pending.extend(rows)
            while len(self._pending) > self._max_pending:
                self._pending.popleft()
                self.lost += 1

    def _run(self):
        while self._running:
            self._myo.run()

    def read_samples(self):
        """Every sample since the last call, shape (n, 8), oldest first; None if none."""
        with self._lock:
            if not self._pending:
                return None
            block = np.array(self._pending)
            self._pending.clear()
        return block

    def read_emg(self):
        """The newest sample since the last call, shape (8,), or None; older ones are dropped.

        The polling interface of earlier versions; ``LiveEmgSource`` reads
        ``read_samples()`` and so loses nothing.
        """
        block = self.read_samples()
        return None if block is None else block[-1]

    def close(self):
        """Stop the reader thread and disconnect."""
        self._running = False
        self._thread.join(timeout=1.0)
        self._myo.disconnect()


def open_myo_device(*, tty=None):
    """Connect to a MYO in raw mode (-128..127 at 200 Hz) and start reading.

    Parameters
    ----------
    tty : str, optional
        Serial port of the Bluetooth dongle; pyomyo searches when None.

    Returns
    -------
    PyomyoDevice

    Raises
    ------
    ModuleNotFoundError
        pyomyo is not installed.
    RuntimeError
        No dongle or armband answered.
    """
    pyomyo = _import_pyomyo()
    try:
        # pyomyo opens the dongle in the constructor and raises plain
        # exceptions (ValueError, serial errors) when it or the armband is absent.
        myo = pyomyo.Myo(tty=tty, mode=pyomyo.emg_mode.RAW)
        myo.connect()
    except Exception as error:
        raise RuntimeError(f"no MYO armband found: {error}") from error
    return PyomyoDevice(myo)
