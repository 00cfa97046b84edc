"""Real-time factor of the teleoperated demonstration diagram at a 1 ms plant step.

For each shipped scenario (cotter pin, drawing), simulates the first ``WINDOW`` seconds of a
demonstration ``REPEATS`` times and prints the best real-time factor (simulated seconds per
second; the best run is the one least disturbed by other work on a shared machine), by the
wall clock and by this process's CPU time: as shipped, without visualisation and with the
Meshcat replay recorder (plus the HTML export); then without visualisation with the haptic
loop (master) and CLIK at 500 Hz instead of 1 kHz, the plant still at 1 ms (the tests'
figures are unchanged at that rate: same pin, strokes within 0.05 mm of the 1 kHz runs'
bounds). Then the ceiling: the plant and the task's scene alone (no Python system; the arm
held by a constant gravity-compensating torque), the cost that no change to the Python
systems can remove. Then, from a profile of the cotter-pin run, the CPU time per simulated
second of each system's callbacks (cProfile inflates Python calls, so read the shares, not
the absolute numbers).

    .venv/bin/python benchmarks/bench_demonstration.py
"""

import cProfile
import dataclasses as dc
import gc
import pstats
import tempfile
import time
from pathlib import Path

from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from hemg_drake.control.clik import velocity_columns
from hemg_drake.diagrams.demonstration import build_demonstration_diagram
from hemg_drake.diagrams.slave import SCENE_BUILDERS, solve_arm_positions
from hemg_drake.robots.baxter import FLOOR_Z, add_baxter_arm
from hemg_drake.scenario import load_scenario
from hemg_drake.viz.recording import ReplayRecorder

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
WINDOW = 3.0
REPEATS = 3


def run(scenario, *, record):
    """Simulate ``WINDOW`` s of a demonstration; (wall s, CPU s, export s or None, bytes)."""
    recorder = ReplayRecorder(floor_z=FLOOR_Z) if record else None
    built = build_demonstration_diagram(scenario, seed=scenario.seed, recorder=recorder)
    simulator = Simulator(built.diagram)
    simulator.Initialize()
    if recorder is not None:
        recorder.start()
    wall, cpu = time.perf_counter(), time.process_time()
    simulator.AdvanceTo(WINDOW)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    export, size = None, 0
    if recorder is not None:
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            path = recorder.stop_and_export(Path(folder) / "replay.html")
            export, size = time.perf_counter() - start, path.stat().st_size
    del built, simulator
    gc.collect()  # releases the Meshcat server
    return wall, cpu, export, size


def plant_alone(scenario):
    """Wall seconds to simulate ``WINDOW`` s of the scenario's plant and scene by themselves."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(scenario.plant, builder)
    arm = add_baxter_arm(plant)
    SCENE_BUILDERS[scenario.task](plant, arm)
    plant.Finalize()
    q = solve_arm_positions(plant, arm, scenario.task_plan().points[0])
    plant.SetDefaultPositions(arm.model_instance, q)
    gravity = plant.CalcGravityGeneralizedForces(plant.CreateDefaultContext())
    hold = builder.AddSystem(
        ConstantVectorSource(-gravity[velocity_columns(plant, arm.model_instance)])
    )
    builder.Connect(hold.get_output_port(), plant.get_actuation_input_port(arm.model_instance))
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(WINDOW)
    return time.perf_counter() - start


def profile_by_system(scenario):
    """CPU seconds per simulated second spent in each system's callbacks (profiled run)."""
    built = build_demonstration_diagram(scenario, seed=scenario.seed)
    simulator = Simulator(built.diagram)
    simulator.Initialize()
    profile = cProfile.Profile()
    profile.runcall(simulator.AdvanceTo, WINDOW)
    stats = pstats.Stats(profile).stats
    shares = {}
    for (filename, _, name), row in stats.items():
        if name.startswith(("_calc", "_update")) and "hemg_drake" in filename:
            module = Path(filename).stem
            shares[f"{module}.{name}"] = row[3] / WINDOW  # cumulative time
    return shares, sum(row[2] for row in stats.values()) / WINDOW


def main():
    print(f"demonstration diagram, 1 ms plant step, {WINDOW:g} s, best of {REPEATS}")
    for name in ("cotter_pin", "drawing"):
        scenario = load_scenario(SCENARIOS / f"{name}.yaml")
        slower = scenario.replaced(
            master=dc.replace(scenario.master, period=2e-3),
            clik=dc.replace(scenario.clik, period=2e-3),
        )
        variants = (
            ("recorder off", scenario, False),
            ("recorder on ", scenario, True),
            ("500 Hz loops", slower, False),
        )
        for label, variant, record in variants:
            runs = [run(variant, record=record) for _ in range(REPEATS)]
            wall, cpu = min(r[0] for r in runs), min(r[1] for r in runs)
            export, size = min(runs)[2:]
            line = (
                f"{name:10s} {label}: "
                f"real-time factor {WINDOW / wall:4.2f}x wall, {WINDOW / cpu:4.2f}x CPU"
            )
            if record:
                line += f"  (HTML export {export:.2f} s, {size / 1e6:.1f} MB)"
            print(line)
        wall = min(plant_alone(scenario) for _ in range(REPEATS))
        print(f"{name:10s} plant alone : real-time factor {WINDOW / wall:4.2f}x wall (ceiling)")
    scenario = load_scenario(SCENARIOS / "cotter_pin.yaml")
    shares, total = profile_by_system(scenario)
    print(f"\ncotter pin, profiled: {total * 1e3:.0f} ms of CPU per simulated second in all")
    print("cumulative CPU per simulated second by callback (nested calls counted in each):")
    for key, value in sorted(shares.items(), key=lambda item: -item[1])[:12]:
        print(f"  {key:40s} {value * 1e3:6.0f} ms")


if __name__ == "__main__":
    main()
