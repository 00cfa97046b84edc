"""Real-time factor of the teleoperated demonstration diagram at a 1 ms plant step.

For each shipped scenario (cotter pin, drawing), simulates one whole demonstration (the
scenario's ``duration``) ``REPEATS`` times and prints the best real-time factor (simulated
seconds per second; the best run is the one least disturbed by other work on a shared
machine), by the wall clock and by this process's CPU time:

- as shipped (haptic loop, CLIK and operator hand at 1 kHz), without visualisation;
- the same with the Meshcat replay recorder (plus the HTML export's time and size);
- with the haptic loop (master) and CLIK at 500 Hz, the plant still at 1 ms;
- the plant and the task's scene alone (no Python system; the arm held by a constant
  gravity-compensating torque): the floor that no change to the Python systems can lower
  (the drawing's pen contacts the paper in half of the run, which it does not reach here).

Each process first runs a few steps of a throw-away diagram: numba loads its compiled
kernels (the PD and the CLIK steps) on first use, about 0.5 s once per process, which
is not part of any simulation's rate. Then, for the run as shipped, the wall time per
simulated second spent in each Python system's own callbacks (nested callbacks
subtracted), measured in place with a timer around every callback, and the rest (Drake:
the plant, SceneGraph, the framework).

    .venv/bin/python benchmarks/bench_demonstration.py
"""

import collections
import functools
import gc
import inspect
import tempfile
import time
from pathlib import Path

from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource

from hemg_drake.control.clik import velocity_columns
from hemg_drake.diagrams.demonstration import build_demonstration_diagram
from hemg_drake.control.ik import solve_tool_point_ik
from hemg_drake.diagrams.station import SCENE_BUILDERS
from hemg_drake.robots.baxter import FLOOR_Z, add_baxter_arm
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.viz.recording import ReplayRecorder

REPEATS = 3


def warm_up(scenario):
    """A few steps of a throw-away diagram, so numba's one-off loading is not timed."""
    Simulator(build_demonstration_diagram(scenario, seed=scenario.seed).diagram).AdvanceTo(0.01)


def run(scenario, *, record):
    """Simulate one demonstration; (wall s, CPU s, export s or None, bytes)."""
    recorder = ReplayRecorder(floor_z=FLOOR_Z) if record else None
    built = build_demonstration_diagram(scenario, seed=scenario.seed, recorder=recorder)
    simulator = Simulator(built.diagram)
    simulator.Initialize()
    if recorder is not None:
        recorder.start()
    wall, cpu = time.perf_counter(), time.process_time()
    simulator.AdvanceTo(scenario.duration)
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
    """Wall seconds to simulate the scenario's duration of its plant and scene by themselves."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(scenario.plant, builder)
    arm = add_baxter_arm(plant)
    scene = SCENE_BUILDERS[scenario.task](
        plant, arm, params=scenario.scene_params(), X_WT=scenario.X_WT()
    )
    plant.Finalize()
    if hasattr(scene, "add_systems"):
        scene.add_systems(builder)  # the pin's detent
    q = solve_tool_point_ik(plant, arm, scenario.task_plan().points[0])
    plant.SetDefaultPositions(arm.model_instance, q)
    gravity = plant.CalcGravityGeneralizedForces(plant.CreateDefaultContext())
    hold = builder.AddSystem(
        ConstantVectorSource(-gravity[velocity_columns(plant, arm.model_instance)])
    )
    builder.Connect(hold.get_output_port(), plant.get_actuation_input_port(arm.model_instance))
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(scenario.duration)
    return time.perf_counter() - start


class CallbackTimer:
    """Times every callback of this package's LeafSystems in place: own time, nested excluded.

    While active, each ``_calc*``/``_update*`` method of a LeafSystem subclass defined in
    ``hemg_drake`` is wrapped by a timer (about 0.3 us per call); a callback that evaluates
    another system's output (the master asking for the operator's hand force) is charged
    without the nested callback's time.
    """

    def __init__(self):
        self.seconds = collections.Counter()
        self.calls = collections.Counter()
        self._nested = []
        self._originals = []

    def _wrap(self, key, method):
        @functools.wraps(method)
        def timed(*args, **kwargs):
            self._nested.append(0.0)
            start = time.perf_counter()
            try:
                return method(*args, **kwargs)
            finally:
                elapsed = time.perf_counter() - start
                self.seconds[key] += elapsed - self._nested.pop()
                self.calls[key] += 1
                if self._nested:
                    self._nested[-1] += elapsed

        return timed

    def __enter__(self):
        import hemg_drake  # every module that defines a system is imported by the diagram

        seen = set()
        stack = list(LeafSystem.__subclasses__())
        while stack:
            cls = stack.pop()
            stack.extend(cls.__subclasses__())
            if cls in seen or not cls.__module__.startswith(hemg_drake.__name__):
                continue
            seen.add(cls)
            for name, method in list(vars(cls).items()):
                if name.startswith(("_calc", "_update")) and inspect.isfunction(method):
                    self._originals.append((cls, name, method))
                    setattr(cls, name, self._wrap(f"{cls.__name__}.{name}", method))
        return self

    def __exit__(self, *exc):
        for cls, name, method in self._originals:
            setattr(cls, name, method)


def time_by_system(scenario):
    """(wall s per simulated s, {callback: (s per simulated s, calls per simulated s)})."""
    with CallbackTimer() as timer:
        built = build_demonstration_diagram(scenario, seed=scenario.seed)
        simulator = Simulator(built.diagram)
        simulator.Initialize()
        timer.seconds.clear()
        timer.calls.clear()
        start = time.perf_counter()
        simulator.AdvanceTo(scenario.duration)
        wall = time.perf_counter() - start
    per_second = {
        key: (seconds / scenario.duration, timer.calls[key] / scenario.duration)
        for key, seconds in timer.seconds.items()
    }
    return wall / scenario.duration, per_second


def main():
    print(f"demonstration diagram, 1 ms plant step, whole demonstrations, best of {REPEATS}")
    for name in ("cotter_pin", "drawing"):
        scenario = load_scenario(shipped_scenario(name))
        warm_up(scenario)
        slower = scenario.replaced(["master.period=2e-3", "clik.period=2e-3"])
        variants = (
            ("recorder off", scenario, False),
            ("recorder on ", scenario, True),
            ("500 Hz loops", slower, False),
        )
        duration = scenario.duration
        for label, variant, record in variants:
            runs = [run(variant, record=record) for _ in range(REPEATS)]
            wall, cpu = min(r[0] for r in runs), min(r[1] for r in runs)
            export, size = min(runs)[2:]
            line = (
                f"{name:10s} {label}: {duration:g} s, "
                f"real-time factor {duration / wall:4.2f}x wall, {duration / cpu:4.2f}x CPU"
            )
            if record:
                line += f"  (HTML export {export:.2f} s, {size / 1e6:.1f} MB)"
            print(line)
        wall = min(plant_alone(scenario) for _ in range(REPEATS))
        print(f"{name:10s} plant alone : real-time factor {duration / wall:4.2f}x wall (floor)")

    for name in ("cotter_pin", "drawing"):
        scenario = load_scenario(shipped_scenario(name))
        wall, systems = time_by_system(scenario)
        python = sum(seconds for seconds, _ in systems.values())
        print(
            f"\n{name}, timed in place: {wall * 1e3:.0f} ms of wall time per simulated second, "
            f"{python * 1e3:.0f} ms in Python callbacks, {(wall - python) * 1e3:.0f} ms in Drake"
        )
        for key, (seconds, calls) in sorted(systems.items(), key=lambda item: -item[1][0]):
            print(
                f"  {key:45s} {seconds * 1e3:6.1f} ms  {calls:5.0f} calls  "
                f"{seconds / calls * 1e6:6.1f} us/call"
            )


if __name__ == "__main__":
    main()
