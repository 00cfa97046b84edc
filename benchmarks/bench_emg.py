"""EMG chain throughput: offline moving_rms, and the three systems in a diagram.

Prints the CPU time of ``moving_rms`` on 10^7 samples x 8 channels (int8, as the MYO
delivers them) for both envelope forms, and the CPU time per simulated second of a source
(synthetic, then file replay) -> RmsEnvelope -> VariableGain at 200 Hz. CPU time
(``time.process_time``), so other processes on the machine do not count.
"""

import tempfile
import time
from pathlib import Path

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from hemg_drake.emg.calibration import EmgCalibration
from hemg_drake.emg.chain import add_emg_gain_chain
from hemg_drake.emg.config import MYO_PERIOD
from hemg_drake.emg.envelope import moving_rms
from hemg_drake.emg.sources import (
    make_file_emg_source,
    make_synthetic_emg_source,
    save_emg_recording,
    synthesize_emg,
)

N_SAMPLES = 10**7
SIMULATED_SECONDS = 20.0


def bench_moving_rms():
    samples = np.random.default_rng(0).integers(-128, 128, size=(N_SAMPLES, 8), dtype=np.int8)
    for per_channel in (False, True):
        start = time.process_time()
        moving_rms(samples, 20, per_channel=per_channel)
        elapsed = time.process_time() - start
        form = "per-channel" if per_channel else "sum (paper)"
        print(
            f"moving_rms {form:12s} L_win=20, 10^7 x 8: {elapsed:6.2f} s CPU, "
            f"{N_SAMPLES / elapsed:.3g} samples/s"
        )


def bench_diagram(source, label):
    """CPU time per simulated second of ``source`` -> RMS -> gain."""
    calibration = EmgCalibration.from_recordings(
        synthesize_emg(np.zeros(400), seed=1), synthesize_emg(np.ones(400), seed=2)
    )
    builder = DiagramBuilder()
    builder.AddSystem(source)
    if source.num_input_ports():
        activation = builder.AddSystem(ConstantVectorSource([0.5]))
        builder.Connect(activation.get_output_port(), source.GetInputPort("activation"))
    _, gain = add_emg_gain_chain(builder, source.GetOutputPort("emg"), calibration=calibration)
    # The gain is computed on demand: a 200 Hz logger stands in for its consumer.
    LogVectorOutput(gain.get_gain_output_port(), builder, publish_period=MYO_PERIOD)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    diagram.SetRandomContext(simulator.get_mutable_context(), RandomGenerator(0))
    simulator.Initialize()
    start = time.process_time()
    simulator.AdvanceTo(SIMULATED_SECONDS)
    per_second = (time.process_time() - start) / SIMULATED_SECONDS
    print(
        f"diagram {label} -> RMS -> gain at 200 Hz: {1e3 * per_second:.1f} ms CPU per "
        f"simulated s ({1 / per_second:.0f}x real time)"
    )


if __name__ == "__main__":
    bench_moving_rms()
    bench_diagram(make_synthetic_emg_source(), "synthetic source")
    with tempfile.TemporaryDirectory() as folder:
        recording = Path(folder) / "recording.npz"
        save_emg_recording(recording, synthesize_emg(np.full(1000, 0.5), seed=3))
        source = make_file_emg_source(filename=recording, at_end="loop", duration=SIMULATED_SECONDS)
        bench_diagram(source, "file source")
