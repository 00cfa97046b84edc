"""Real-time factor of the arm simulation at a 1 ms step, with and without the Meshcat recorder.

Prints simulated seconds per wall second for 10 s of simulated time:
- bare arm: the plant alone (no controller; the arm swings under gravity from home), with
  Drake's default discrete solver (SAP, which enforces the joint limits as constraints) and
  with TAMSI (joint limits as penalty forces), for comparison,
- demo: the waypoint tour under VariableGainPd + gravity compensation (a Python system at 1 kHz),
each without and with a replay recording (the scenario's visualization: 32 frames/s), plus the
cost of exporting the HTML.
"""

import gc
import tempfile
import time
from functools import partial
from pathlib import Path

from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, DiscreteContactApproximation
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from hemg_drake.diagrams.arm_demo import build_arm_demo
from hemg_drake.diagrams.visualization import Visualization, apply_visualization
from hemg_drake.robots.baxter import FLOOR_Z, add_baxter_arm
from hemg_drake.scenario import Scenario
from hemg_drake.viz.recording import ReplayRecorder

SIMULATED_SECONDS = 10.0
TIME_STEP = 1e-3


def build_bare_arm(visualization, approximation=None):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=TIME_STEP)
    if approximation is not None:
        plant.set_discrete_contact_approximation(approximation)
    add_baxter_arm(plant)  # starts at home
    plant.Finalize()
    if visualization is not None:
        apply_visualization(Scenario().visualization, builder, plant=plant,
                            scene_graph=scene_graph, visualization=visualization)  # fmt: skip
    return builder.Build()


def build_demo(visualization):
    return build_arm_demo(
        duration=SIMULATED_SECONDS, time_step=TIME_STEP, visualization=visualization
    )[0]


def measure(build, record, out_dir, seconds=SIMULATED_SECONDS):
    """Return (real-time factor, export seconds or None)."""
    visualization = Visualization() if record else None
    diagram = build(visualization)
    simulator = Simulator(diagram)
    simulator.Initialize()
    if record:
        recorder = ReplayRecorder(floor_z=FLOOR_Z)
        recorder.start(diagram, visualization.meshcat)
    start = time.perf_counter()
    simulator.AdvanceTo(seconds)
    rate = seconds / (time.perf_counter() - start)
    export = None
    if record:
        start = time.perf_counter()
        recorder.stop_and_export(Path(out_dir) / "replay.html")
        export = time.perf_counter() - start
    gc.collect()  # release the Meshcat server before the next run
    return rate, export


def main():
    print(f"{SIMULATED_SECONDS:g} s simulated at a {TIME_STEP * 1e3:g} ms step")
    with tempfile.TemporaryDirectory() as out_dir:
        tamsi = partial(build_bare_arm, approximation=DiscreteContactApproximation.kTamsi)
        cases = (("bare arm", build_bare_arm), ("bare TAMSI", tamsi), ("demo (PD)", build_demo))
        # numba loads the PD's compiled step on first use (about 0.5 s once per process).
        measure(build_demo, False, out_dir, seconds=0.01)
        for label, build in cases:
            for record in (False, True):
                rate, export = measure(build, record, out_dir)
                state = "on " if record else "off"
                line = f"{label:10s} recorder={state}  real-time factor {rate:6.1f}x"
                if export is not None:
                    size = (Path(out_dir) / "replay.html").stat().st_size / 1e6
                    line += f"  (HTML export {export:.2f} s, {size:.1f} MB)"
                print(line)


if __name__ == "__main__":
    main()
