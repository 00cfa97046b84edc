"""Real-time factor of the two task scenes followed by CLIK + PD at a constant gain (1 ms step).

The diagrams of ``tests/tasks``: the arm, the task's scene, ``add_plan_follower`` (plan ->
Clik -> VariableGainPd at K = 100, two Python systems at 1 kHz) and the scene's force sensor
logged at 0.01 s, for the whole default plan (cotter pin 3.5 s, drawing 11.6 s), each without
and with a ReplayRecorder (32 frames/s; for drawing the ink is added before the export).
Prints simulated seconds per wall-clock second and per CPU second of this process (the
machine is shared: the CPU figure is what an idle core would give), and the outcome.
"""

import gc
import tempfile
import time
from pathlib import Path

from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from hemg_drake.robots.baxter import FLOOR_Z, add_baxter_arm
from hemg_drake.tasks.cotter_pin import add_cotter_pin_scene, default_cotter_pin_plan
from hemg_drake.tasks.drawing import add_drawing_scene, default_drawing_plan
from hemg_drake.tasks.follow import add_plan_follower
from hemg_drake.viz.ink import add_ink_to_recording, in_contact, ink_strokes
from hemg_drake.viz.recording import ReplayRecorder

GAIN = 100.0


def run(task, record, out_dir, duration=None):
    """Simulate one task's default plan (or its first ``duration`` s).

    Returns (wall and CPU real-time factors, outcome).
    """
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    arm = add_baxter_arm(plant)
    add_scene, plan = {
        "cotter pin": (add_cotter_pin_scene, default_cotter_pin_plan()),
        "drawing": (add_drawing_scene, default_drawing_plan()),
    }[task]
    scene = add_scene(plant, arm)
    plant.Finalize()
    plant.SetDefaultPositions(arm.model_instance, arm.home_positions)
    add_plan_follower(builder, plant=plant, arm=arm, plan=plan, gain=GAIN)
    force_log = LogVectorOutput(scene.force_output_port(builder), builder, 0.01)
    state_log = LogVectorOutput(plant.get_state_output_port(arm.model_instance), builder, 0.01)
    recorder = ReplayRecorder(floor_z=FLOOR_Z) if record else None
    if record:
        recorder.add_to_builder(builder, scene_graph)
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    if record:
        recorder.start()
    duration = plan.end_time if duration is None else duration
    start, start_cpu = time.perf_counter(), time.process_time()
    simulator.AdvanceTo(duration)
    rate = duration / (time.perf_counter() - start)
    cpu_rate = duration / (time.process_time() - start_cpu)

    context = simulator.get_context()
    plant_context = plant.GetMyContextFromRoot(context)
    if task == "cotter pin":
        outcome = f"pin out {scene.pin_displacement(plant_context) * 1e3:.0f} mm"
    else:
        fk = plant.CreateDefaultContext()
        states = state_log.FindLog(context)
        p_WP = []
        for q in states.data()[:7].T:
            plant.SetPositions(fk, arm.model_instance, q)
            p_WP.append(arm.tool_frame.CalcPoseInWorld(fk).translation())
        touching = in_contact(force_log.FindLog(context).data().T)
        outcome = f"{len(ink_strokes(states.sample_times(), p_WP, touching))} ink strokes"
        if record:
            add_ink_to_recording(
                recorder.meshcat, states.sample_times(), p_WP, touching,
                height=scene.paper_height + 5e-4,
            )
    if record:
        recorder.stop_and_export(Path(out_dir) / "replay.html")
    gc.collect()  # release the Meshcat server before the next run
    return rate, cpu_rate, outcome


def main():
    print(f"plan followed at K = {GAIN:g}, 1 ms plant step")
    with tempfile.TemporaryDirectory() as out_dir:
        # numba loads the CLIK's and the PD's compiled steps on first use (about 0.5 s once
        # per process), which is not part of a simulation's rate.
        run("cotter pin", False, out_dir, duration=0.01)
        for task in ("cotter pin", "drawing"):
            for record in (False, True):
                rate, cpu_rate, outcome = run(task, record, out_dir)
                state = "on " if record else "off"
                print(
                    f"{task:10s} recorder={state}  real-time factor {rate:5.2f}x wall, "
                    f"{cpu_rate:5.2f}x CPU  ({outcome})"
                )


if __name__ == "__main__":
    main()
