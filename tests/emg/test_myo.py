"""The optional live MYO adapter, with a fake pyomyo module (no armband needed)."""

import sys
import time
import types

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from hemg_drake.emg.sources import LiveEmgSource, open_myo_device


class FakeMyo:
    """Stands in for pyomyo.Myo: each run() delivers the next scripted sample."""

    instances = []

    def __init__(self, tty=None, mode=None):
        self.tty, self.mode = tty, mode
        self.handlers, self.connected, self.sent = [], False, 0
        FakeMyo.instances.append(self)

    def connect(self):
        self.connected = True

    def add_emg_handler(self, handler):
        self.handlers.append(handler)

    def run(self):
        sample = tuple(int(v) for v in (np.arange(8) - 4 + self.sent) % 100)
        self.sent += 1
        for handler in self.handlers:
            handler(sample, 0)
        time.sleep(0.001)

    def disconnect(self):
        self.connected = False


class NoDongleMyo(FakeMyo):
    def __init__(self, tty=None, mode=None):
        raise ValueError("Myo dongle not found!")


def _fake_pyomyo(myo_class):
    module = types.ModuleType("pyomyo")
    module.Myo = myo_class
    module.emg_mode = types.SimpleNamespace(RAW=3)
    return module


def _first_sample(device, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        sample = device.read_emg()
        if sample is not None:
            return sample
        time.sleep(0.002)
    raise AssertionError("the reader thread delivered nothing")


def test_missing_extra_gives_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyomyo", None)  # import pyomyo -> ImportError
    with pytest.raises(ModuleNotFoundError, match=r"pip install 'hemg-drake\[myo\]'"):
        open_myo_device()


def test_missing_armband_gives_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyomyo", _fake_pyomyo(NoDongleMyo))
    with pytest.raises(RuntimeError, match="no MYO armband found: Myo dongle not found"):
        open_myo_device()


def test_device_streams_raw_samples_into_the_live_source(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyomyo", _fake_pyomyo(FakeMyo))
    device = open_myo_device(tty="/dev/fake")
    try:
        myo = FakeMyo.instances[-1]
        assert myo.connected and myo.mode == 3 and myo.tty == "/dev/fake"
        sample = _first_sample(device)
        assert sample.shape == (8,)
        # Consecutive channels of a fake sample differ by 1 (mod 100).
        assert np.all(np.diff(sample) % 100 == 1)

        simulator = Simulator(LiveEmgSource(device=device))
        time.sleep(0.02)  # the reader thread has a newer sample waiting
        simulator.AdvanceTo(0.001)  # the poll at t = 0 takes it
        source = simulator.get_system()
        emg = source.get_emg_output_port().Eval(simulator.get_context())
        assert np.all(np.diff(emg) % 100 == 1)
    finally:
        device.close()
    assert not myo.connected
