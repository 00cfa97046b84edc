"""Real-device paths without the devices: live sEMG through LibEMG's shared memory, the
master-device adapter, and the robomimic export.

    .venv/bin/python benchmarks/bench_devices.py

1. ``LibEmgSharedMemory.read_samples`` per call (2 new samples in a 1000-row ring).
2. A mimic LibEMG streamer process writing MYO packets (2 samples every 10 ms, its own
   clock) into shared memory, read by ``LiveEmgSource`` -> RMS -> gain in a simulator at
   real-time rate for a few seconds: the counters show what drift does.
3. ``DeviceMaster`` at 1 kHz with a trivial device: cost per step.
4. ``export_robomimic`` of a demonstration-sized dataset: time and file size.
"""

import multiprocessing
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from hemg_drake.emg.chain import add_emg_gain_chain
from hemg_drake.emg.libemg import LibEmgSharedMemory
from hemg_drake.emg.libemg_writer import StreamerMemory
from hemg_drake.emg.sources import LiveEmgSource

CHANNELS = 8


def _streamer(tag, rows, lock, period, seconds, ready):
    """A LibEMG-like MYO streamer: 2 int8-valued samples per packet, every 2 periods."""
    from multiprocessing import resource_tracker

    resource_tracker.register = resource_tracker.unregister = lambda name, rtype: None
    memory = StreamerMemory(tag, rows, CHANNELS)
    rng = np.random.default_rng(0)
    ready.set()
    start = time.monotonic()
    j = 0
    while time.monotonic() - start < seconds:
        packet = rng.integers(-128, 128, (2, CHANNELS)).astype(float)
        memory.write(packet[::-1], lock, lock)
        j += 2
        # Sleep to the packet's due time on the streamer's own clock.
        time.sleep(max(0.0, start + j * period - time.monotonic()))
    time.sleep(0.5)
    memory.close()


def bench_read():
    context = multiprocessing.get_context("fork")
    lock, ready = context.Lock(), context.Event()
    tag = f"hemg_bench_{uuid.uuid4().hex[:10]}"
    # A fast streamer (no sleep between packets would flood: use a 0.1 ms period).
    process = context.Process(target=_streamer, args=(tag, 1000, lock, 1e-4, 2.0, ready))
    process.start()
    ready.wait(10)
    reader = LibEmgSharedMemory(channels=CHANNELS, tag=tag, lock=lock, count_lock=lock)
    calls, samples, elapsed = 0, 0, 0.0
    deadline = time.monotonic() + 1.5
    while time.monotonic() < deadline:
        t0 = time.perf_counter()
        block = reader.read_samples()
        elapsed += time.perf_counter() - t0
        calls += 1
        samples += 0 if block is None else len(block)
        time.sleep(0.0002)
    print(f"read_samples: {1e6 * elapsed / calls:.1f} us per call, {samples} samples in "
          f"{calls} calls, lost {reader.lost}, retries {reader.retries}")  # fmt: skip
    reader.close()
    process.join(10)


class NewestOnly:
    """The earlier policy, for comparison: the newest sample of each poll, the rest lost."""

    def __init__(self, device):
        self.device = device

    def read_samples(self):
        block = self.device.read_samples()
        return None if block is None else block[-1:]


def bench_live_chain(seconds=5.0, rate=200.0, newest_only=False, locks=True):
    context = multiprocessing.get_context("fork")
    lock, ready = context.Lock(), context.Event()
    tag = f"hemg_bench_{uuid.uuid4().hex[:10]}"
    args = (tag, 1000, lock, 1 / rate, seconds + 1, ready)
    process = context.Process(target=_streamer, args=args)
    process.start()
    ready.wait(10)
    shared = {"lock": lock, "count_lock": lock} if locks else {}
    reader = LibEmgSharedMemory(channels=CHANNELS, tag=tag, **shared)
    builder = DiagramBuilder()
    source = builder.AddSystem(LiveEmgSource(device=NewestOnly(reader) if newest_only else reader))
    add_emg_gain_chain(builder, source.get_emg_output_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.set_target_realtime_rate(1.0)
    simulator.Initialize()
    t0 = time.perf_counter()
    simulator.AdvanceTo(seconds)
    wall = time.perf_counter() - t0
    counters = source.counters_dict(simulator.get_context())
    policy = "newest sample per poll" if newest_only else "queue"
    policy += "" if locks else ", no locks"
    print(f"live chain ({policy}), device at {rate:g} Hz, {seconds:g} s at real-time rate "
          f"(wall {wall:.2f} s): streamer wrote ~{int(reader._count[0, 0])}, {counters}, "
          f"reader retries {reader.retries}, realigned {reader.realigned}")
    reader.close()
    process.join(15)


def bench_device_master(steps=5000):
    from hemg_drake.teleop.devices import DeviceMaster

    class Still:
        def position(self):
            return [0.0, 0.01, 0.0]

        def apply_force(self, f):
            pass

    builder = DiagramBuilder()
    master = builder.AddSystem(DeviceMaster(device=Still()))
    force = builder.AddSystem(ConstantVectorSource(np.zeros(3)))
    builder.Connect(force.get_output_port(), master.get_motor_force_input_port())
    simulator = Simulator(builder.Build())
    t0 = time.perf_counter()
    simulator.AdvanceTo(steps * 1e-3)
    per_step = (time.perf_counter() - t0) / steps
    print(f"DeviceMaster: {1e6 * per_step:.1f} us per 1 ms step")


def bench_export():
    from hemg_drake.learning.demos import Demonstration
    from hemg_drake.learning.export import export_robomimic, load_robomimic

    rng = np.random.default_rng(0)
    demos = []
    for seed in range(4):  # 4 demonstrations of 12 s: the drawing's size
        n, n_emg = 1200, 2400
        demos.append(Demonstration(
            seed=seed, time=np.arange(n) * 0.01, p_WE=rng.normal(size=(n, 3)),
            v_WE=rng.normal(size=(n, 3)), p_MS=rng.normal(size=(n, 3)),
            p_WE_desired=rng.normal(size=(n, 3)), envelope=rng.uniform(size=n),
            activation=rng.uniform(size=n), gain=rng.uniform(size=n), f_WE=rng.normal(size=(n, 3)),
            emg_time=np.arange(n_emg) / 200, emg=rng.integers(-128, 128, (n_emg, 8)).astype(float),
            muscle_activation=rng.uniform(size=n_emg),
        ))  # fmt: skip
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "demos.hdf5"
        t0 = time.perf_counter()
        export_robomimic(path, demos, {"task": "drawing"})
        t1 = time.perf_counter()
        load_robomimic(path)
        t2 = time.perf_counter()
        print(f"export_robomimic, 4 x 1200 samples: {1e3 * (t1 - t0):.0f} ms, "
              f"{path.stat().st_size / 1e6:.2f} MB; load_robomimic {1e3 * (t2 - t1):.0f} ms")


if __name__ == "__main__":
    chains = {
        "chain": lambda: bench_live_chain(),
        "newest": lambda: bench_live_chain(newest_only=True),
        "fast": lambda: bench_live_chain(rate=202.0),
        "slow": lambda: bench_live_chain(rate=198.0),
        "lockfree": lambda: bench_live_chain(locks=False),
    }
    which = sys.argv[1:] or ["read", *chains, "master", "export"]
    for name in which:
        {"read": bench_read, "master": bench_device_master, "export": bench_export,
         **chains}[name]()  # fmt: skip
