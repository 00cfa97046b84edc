"""Live MYO armband through the optional ``pyomyo`` driver (extra ``hemg-drake[myo]``).

All device access lives here; ``LiveEmgSource`` only calls ``read_emg()``, so
it is tested with a fake device and this module with a fake ``pyomyo``.
"""

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


class PyomyoDevice:
    """A connected MYO streaming raw sEMG, read by a background thread.

    pyomyo delivers samples through a handler called from ``Myo.run()``; a
    daemon thread keeps calling it and the handler keeps the newest sample,
    which ``read_emg()`` hands out once.

    Parameters
    ----------
    myo : pyomyo.Myo
        Already connected, in raw EMG mode.
    """

    def __init__(self, myo):
        self._myo = myo
        self._lock = threading.Lock()
        self._newest = None
        self._running = True
        myo.add_emg_handler(self._on_emg)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _on_emg(self, emg, movement):
        with self._lock:
            self._newest = np.asarray(emg[:8], dtype=float)

    def _run(self):
        while self._running:
            self._myo.run()

    def read_emg(self):
        """The newest sample since the last call, shape (8,), or None."""
        with self._lock:
            sample, self._newest = self._newest, None
        return sample

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
