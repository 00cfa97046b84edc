"""EMG chain throughput: offline moving_rms, and the three systems in a diagram.

Prints samples per second of ``moving_rms`` on 10^7 samples x 8 channels (int8,
as the MYO delivers them) for both envelope forms, and the wall-clock cost per
simulated second of a source (synthetic, then file replay) -> RmsEnvelope ->
VariableGain at 200 Hz.
"""

import tempfile
import time
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.chain import add_emg_gain_chain
from hemg_drake.emg.envelope import moving_rms
from hemg_drake.emg.sources import (
    MYO_PERIOD,
    FileEmgSource,
    SyntheticEmgSource,
    synthesize_emg,
)
from hemg_drake.fileio import save_npz_atomic

N_SAMPLES = 10**7
SIMULATED_SECONDS = 20.0


def bench_moving_rms():
    samples = np.random.default_rng(0).integers(-128, 128, size=(N_SAMPLES, 8), dtype=np.int8)
    for per_channel in (False, True):
        start = time.perf_counter()
        moving_rms(samples, 20, per_channel=per_channel)
        elapsed = time.perf_counter() - start
        form = "per-channel" if per_channel else "sum (paper)"
        print(
            f"moving_rms {form:12s} L_win=20, 10^7 x 8: {elapsed:6.2f} s, "
            f"{N_SAMPLES / elapsed:.3g} samples/s"
        )


def bench_diagram(source, label):
    """Wall-clock cost per simulated second of ``source`` -> RMS -> gain."""
    calibration = EmgCalibration.from_recordings(
        synthesize_emg(np.zeros(400), seed=1), synthesize_emg(np.ones(400), seed=2)
    )
    builder = DiagramBuilder()
    builder.AddSystem(source)
    if source.num_input_ports():
        activation = builder.AddSystem(ConstantVectorSource([0.5]))
        builder.Connect(activation.get_output_port(), source.get_activation_input_port())
    _, gain = add_emg_gain_chain(builder, source.get_emg_output_port(), calibration=calibration)
    # The gain is computed on demand: a 200 Hz logger stands in for its consumer.
    LogVectorOutput(gain.get_gain_output_port(), builder, publish_period=MYO_PERIOD)
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(SIMULATED_SECONDS)
    per_second = (time.perf_counter() - start) / SIMULATED_SECONDS
    print(
        f"diagram {label} -> RMS -> gain at 200 Hz: {1e3 * per_second:.1f} ms per simulated s "
        f"({1 / per_second:.0f}x real time)"
    )


if __name__ == "__main__":
    bench_moving_rms()
    bench_diagram(SyntheticEmgSource(seed=0), "synthetic source")
    with tempfile.TemporaryDirectory() as folder:
        recording = Path(folder) / "recording.npz"
        save_npz_atomic(recording, emg=synthesize_emg(np.full(1000, 0.5), seed=3))
        bench_diagram(FileEmgSource(filename=recording, at_end="loop"), "file source")
