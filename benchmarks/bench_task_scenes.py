"""Real-time factor of the two task scenes followed by CLIK + PD at a constant gain (1 ms step).

The diagrams of ``tests/tasks``: the shipped scenario's station (plant, scene, CLIK,
VariableGainPd) driven along the default plan at K = 100 by ``build_plan_follower``, the
scene's force logged at 0.01 s, for the whole default plan (cotter pin 3.5 s, drawing
11.7 s), each without and with a ReplayRecorder (32 frames/s; for drawing the ink is added
before the export). Prints simulated seconds per wall-clock second and per CPU second of
this process (the machine is shared: the CPU figure is what an idle core would give), and
the outcome.
"""

import gc
import tempfile
import time
from pathlib import Path

from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from hemg_drake.diagrams.plan_follower import build_plan_follower
from hemg_drake.robots.baxter import FLOOR_Z
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.viz.ink import add_ink_to_recording, in_contact, ink_strokes
from hemg_drake.viz.recording import ReplayRecorder

GAIN = 100.0


def run(task, record, out_dir, duration=None):
    """Simulate one task's default plan (or its first ``duration`` s).

    Returns (wall and CPU real-time factors, outcome).
    """
    scenario = load_scenario(shipped_scenario(task))
    recorder = ReplayRecorder(floor_z=FLOOR_Z) if record else None
    follower = build_plan_follower(scenario, gain=GAIN, recorder=recorder)
    builder = DiagramBuilder()
    diagram = builder.AddSystem(follower.diagram)
    force_log = LogVectorOutput(diagram.GetOutputPort("f_WE"), builder, 0.01)
    point_log = LogVectorOutput(diagram.GetOutputPort("p_WE"), builder, 0.01)
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    if record:
        recorder.start()
    duration = follower.plan.end_time if duration is None else duration
    start, start_cpu = time.perf_counter(), time.process_time()
    simulator.AdvanceTo(duration)
    rate = duration / (time.perf_counter() - start)
    cpu_rate = duration / (time.process_time() - start_cpu)

    context = simulator.get_context()
    plant_context = follower.station.plant_context(context)
    if task == "cotter_pin":
        outcome = f"pin out {follower.scene.pin_displacement(plant_context) * 1e3:.0f} mm"
    else:
        points = point_log.FindLog(context)
        times, p_WE = points.sample_times(), points.data().T
        touching = in_contact(force_log.FindLog(context).data().T)
        outcome = f"{len(ink_strokes(times, p_WE, touching))} ink strokes"
        if record:
            add_ink_to_recording(
                recorder.meshcat, times, p_WE, touching,
                height=follower.scene.paper_height + 5e-4,
            )  # fmt: skip
    if record:
        recorder.stop_and_export(Path(out_dir) / "replay.html")
    gc.collect()  # release the Meshcat server before the next run
    return rate, cpu_rate, outcome


def main():
    print(f"plan followed at K = {GAIN:g}, 1 ms plant step")
    with tempfile.TemporaryDirectory() as out_dir:
        # numba loads the CLIK's and the PD's compiled steps on first use (about 0.5 s once
        # per process), which is not part of a simulation's rate.
        run("cotter_pin", False, out_dir, duration=0.01)
        for task in ("cotter_pin", "drawing"):
            for record in (False, True):
                rate, cpu_rate, outcome = run(task, record, out_dir)
                state = "on " if record else "off"
                print(
                    f"{task:10s} recorder={state}  real-time factor {rate:5.2f}x wall, "
                    f"{cpu_rate:5.2f}x CPU  ({outcome})"
                )


if __name__ == "__main__":
    main()
