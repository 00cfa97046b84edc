"""Real-time factor of the teleoperated demonstration diagram at a 1 ms plant step, before
and after, side by side.

For each shipped scenario (cotter pin, drawing), simulates one whole demonstration (the
scenario's ``duration``) without visualisation and reports the best real-time factor
(simulated seconds per second) by this process's CPU time (the machine is shared: CPU time
is what other work disturbs least) and by the wall clock:

- ``before``: the code at ``--baseline``, a checkout's directory or a git revision of this
  repository (exported with ``git archive`` to a temporary directory; default 9092e60, the
  code before issue 22's Drake-native controllers), run in a subprocess with ``PYTHONPATH``
  set to it;
- ``after``: this checkout's code, likewise in a subprocess;
- the floor: the plant and the task's scene alone (no Python system; the arm held by a
  constant gravity-compensating torque), which no change to the Python systems can lower
  (the drawing's pen contacts the paper in half of the run, which it does not reach here);
  and each side's fraction of it.

The two sides run in turns (before, after, before, after, ...), so a burst of load on the
machine falls on both. Then, for each side, the CPU time per simulated second spent in each
Python system's own callbacks (nested callbacks subtracted; cache-entry callbacks included),
timed in place with a timer around every callback, and the rest (Drake: the plant,
SceneGraph, C++ systems such as ``InverseDynamics``, the framework).

``--variants`` also prints, for this checkout, the run with the Meshcat replay recorder and
with the haptic loop and the CLIK at 500 Hz.

    .venv/bin/python benchmarks/bench_demonstration.py [--baseline DIR] [--rounds N]
"""

import argparse
import collections
import functools
import gc
import inspect
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SCENARIOS = ("cotter_pin", "drawing")
REPEATS = 2  # runs per subprocess; the best counts


def build(scenario, visualization=None):
    """The demonstration diagram of the checkout on the path and a simulator of the
    scenario's seed (the seed a keyword of the builder, or drawn into the context);
    visualised through ``visualization=`` or, on older checkouts, a ``recorder=``."""
    from pydrake.systems.analysis import Simulator

    from hemg_drake.diagrams import demonstration

    parameters = inspect.signature(demonstration.build_demonstration_diagram).parameters
    shown = {}
    if visualization is not None:
        shown = {"visualization" if "visualization" in parameters else "recorder": visualization}
    if "seed" in parameters:
        built = demonstration.build_demonstration_diagram(scenario, seed=scenario.seed, **shown)
        return built, Simulator(built.diagram)
    built = demonstration.build_demonstration_diagram(scenario, **shown)
    context = demonstration.initial_context(built, scenario.seed)
    return built, Simulator(built.diagram, context)


def run(scenario, *, record=False):
    """Simulate one demonstration; (CPU s, wall s, export s or None, bytes)."""
    recorder = visualization = None
    if record:
        from hemg_drake.robots.baxter import FLOOR_Z
        from hemg_drake.viz.recording import ReplayRecorder

        recorder = ReplayRecorder(floor_z=FLOOR_Z)
        try:
            from hemg_drake.diagrams.visualization import Visualization

            visualization = Visualization()
        except ImportError:  # an older checkout: the recorder attaches itself
            visualization = recorder
    built, simulator = build(scenario, visualization)
    simulator.Initialize()
    if recorder is not None:
        if visualization is recorder:
            recorder.start()
        else:
            recorder.start(built.diagram, visualization.meshcat)
    cpu, wall = time.process_time(), time.perf_counter()
    simulator.AdvanceTo(scenario.duration)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    export, size = None, 0
    if recorder is not None:
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            path = recorder.stop_and_export(Path(folder) / "replay.html")
            export, size = time.perf_counter() - start, path.stat().st_size
    del built, simulator
    gc.collect()  # releases the Meshcat server
    return cpu, wall, export, size


def plant_alone(scenario):
    """(CPU s, wall s) to simulate the scenario's duration of its plant and scene alone."""
    from pydrake.multibody.plant import AddMultibodyPlant
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from hemg_drake.control.ik import solve_tool_point_ik
    from hemg_drake.diagrams.station import SCENE_BUILDERS
    from hemg_drake.robots.baxter import add_baxter_arm

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
    context = plant.CreateDefaultContext()
    gravity = plant.GetVelocitiesFromArray(
        arm.model_instance, plant.CalcGravityGeneralizedForces(context)
    )
    hold = builder.AddSystem(ConstantVectorSource(-gravity))
    builder.Connect(hold.get_output_port(), plant.get_actuation_input_port(arm.model_instance))
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    cpu, wall = time.process_time(), time.perf_counter()
    simulator.AdvanceTo(scenario.duration)
    return time.process_time() - cpu, time.perf_counter() - wall


class CallbackTimer:
    """Times every callback of this package's LeafSystems in place: own time, nested excluded.

    While active, each ``_calc*``/``_update*`` method of a LeafSystem subclass defined in
    ``hemg_drake`` is wrapped by a timer (about 0.3 us per call, CPU time); a callback that
    evaluates another system's output (the master asking for the operator's hand force, a
    calc evaluating its cache entry) is charged without the nested callback's time.
    """

    def __init__(self):
        self.seconds = collections.Counter()
        self.calls = collections.Counter()
        self._nested = []
        self._originals = []

    def _wrap(self, key, method):
        clock = time.process_time

        @functools.wraps(method)
        def timed(*args, **kwargs):
            self._nested.append(0.0)
            start = clock()
            try:
                return method(*args, **kwargs)
            finally:
                elapsed = clock() - start
                self.seconds[key] += elapsed - self._nested.pop()
                self.calls[key] += 1
                if self._nested:
                    self._nested[-1] += elapsed

        return timed

    def __enter__(self):
        import hemg_drake
        from pydrake.systems.framework import LeafSystem

        seen = set()
        stack = list(LeafSystem.__subclasses__())
        while stack:
            cls = stack.pop()
            stack.extend(cls.__subclasses__())
            if cls in seen or not cls.__module__.startswith(hemg_drake.__name__):
                continue
            seen.add(cls)
            # TemplateSystem instantiations are named "Name_[float]"-like; keep "Name".
            name = "".join(c for c in cls.__name__ if c.isascii()).removesuffix("_float")
            name = name.rstrip("_")
            for attribute, method in list(vars(cls).items()):
                if attribute.startswith(("_calc", "_update")) and inspect.isfunction(method):
                    self._originals.append((cls, attribute, method))
                    setattr(cls, attribute, self._wrap(f"{name}.{attribute}", method))
        return self

    def __exit__(self, *exc):
        for cls, attribute, method in self._originals:
            setattr(cls, attribute, method)


def time_by_system(scenario):
    """(CPU s per simulated s, {callback: (s per simulated s, calls per simulated s)})."""
    with CallbackTimer() as timer:
        built, simulator = build(scenario)
        simulator.Initialize()
        timer.seconds.clear()
        timer.calls.clear()
        start = time.process_time()
        simulator.AdvanceTo(scenario.duration)
        cpu = time.process_time() - start
    per_second = {
        key: (seconds / scenario.duration, timer.calls[key] / scenario.duration)
        for key, seconds in timer.seconds.items()
    }
    return cpu / scenario.duration, per_second


def measure(profile):
    """This checkout's figures, as a JSON-able dict (the subprocess side)."""
    from hemg_drake.scenario import load_scenario, shipped_scenario

    figures = {}
    for name in SCENARIOS:
        scenario = load_scenario(shipped_scenario(name))
        run(scenario)  # warm-up: imports, first calls
        runs = [run(scenario) for _ in range(REPEATS)]
        floor = [plant_alone(scenario) for _ in range(REPEATS)]
        figures[name] = {
            "duration": scenario.duration,
            "cpu": min(r[0] for r in runs),
            "wall": min(r[1] for r in runs),
            "floor_cpu": min(f[0] for f in floor),
            "floor_wall": min(f[1] for f in floor),
        }
        if profile:
            figures[name]["profile"] = time_by_system(scenario)
    return figures


def variants():
    """The recorder and 500 Hz lines for this checkout (in this process)."""
    from hemg_drake.scenario import load_scenario, shipped_scenario

    for name in SCENARIOS:
        scenario = load_scenario(shipped_scenario(name))
        run(scenario)
        slower = scenario.replaced(["master.period=2e-3", "clik.period=2e-3"])
        for label, variant, record in (("recorder on", scenario, True),
                                       ("500 Hz loops", slower, False)):  # fmt: skip
            runs = [run(variant, record=record) for _ in range(REPEATS)]
            cpu = min(r[0] for r in runs)
            line = f"{name:10s} {label:12s}: {variant.duration / cpu:5.2f}x CPU"
            if record:
                export, size = min(runs)[2:]
                line += f"  (HTML export {export:.2f} s, {size / 1e6:.1f} MB)"
            print(line)


def in_subprocess(path, profile):
    """``measure`` run with ``PYTHONPATH=path`` in a fresh interpreter."""
    environment = dict(os.environ, PYTHONPATH=str(path))
    arguments = [sys.executable, __file__, "--measure"] + (["--profile"] if profile else [])
    result = subprocess.run(
        arguments, env=environment, cwd=path, capture_output=True, text=True, check=False
    )
    if result.returncode != 0:
        raise RuntimeError(f"measuring {path} failed:\n{result.stderr[-2000:]}")
    return json.loads(result.stdout.strip().splitlines()[-1])


def best(rounds, side, name, key):
    return min(r[side][name][key] for r in rounds)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--baseline", default="9092e60", help="directory or git revision timed as 'before'"
    )
    parser.add_argument("--rounds", type=int, default=2, help="turns of before/after")
    parser.add_argument("--variants", action="store_true")
    parser.add_argument("--measure", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--profile", action="store_true", help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.measure:
        print(json.dumps(measure(arguments.profile)))
        return

    here = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as exported:
        baseline = Path(arguments.baseline)
        if not baseline.is_dir():
            archive = subprocess.run(
                ["git", "-C", str(here), "archive", arguments.baseline],
                capture_output=True, check=True,
            )  # fmt: skip
            subprocess.run(["tar", "-x", "-C", exported], input=archive.stdout, check=True)
            baseline = Path(exported)
        report({"before": baseline, "after": here}, arguments)


def report(sides, arguments):
    """Run both sides in turns and print the figures side by side."""
    rounds = []
    for turn in range(arguments.rounds):
        profile = turn == arguments.rounds - 1
        rounds.append({side: in_subprocess(path, profile) for side, path in sides.items()})
    print(
        f"demonstration diagram, 1 ms plant step, whole demonstrations, recorder off; "
        f"best of {arguments.rounds} x {REPEATS} runs per side; real-time factors "
        f"(CPU time / wall clock); before = {arguments.baseline}, after = {sides['after']}"
    )
    for name in SCENARIOS:
        duration = rounds[0]["after"][name]["duration"]
        floor = duration / min(best(rounds, side, name, "floor_cpu") for side in sides)
        floor_wall = duration / min(best(rounds, side, name, "floor_wall") for side in sides)
        cells = []
        for side in sides:
            cpu = duration / best(rounds, side, name, "cpu")
            wall = duration / best(rounds, side, name, "wall")
            cells.append(f"{side} {cpu:5.2f}x / {wall:5.2f}x ({cpu / floor:.2f} of the floor)")
        print(f"  {name:10s} {duration:4.1f} s: " + "   ".join(cells))
        print(f"  {name:10s} plant and scene alone (the floor): {floor:5.2f}x / {floor_wall:5.2f}x")

    for name in SCENARIOS:
        for side in sides:
            cpu, systems = rounds[-1][side][name]["profile"]
            python = sum(seconds for seconds, _ in systems.values())
            print(
                f"\n{name}, {side}, timed in place: {cpu * 1e3:.0f} ms of CPU per simulated "
                f"second, {python * 1e3:.0f} ms in Python callbacks, "
                f"{(cpu - python) * 1e3:.0f} ms in Drake"
            )
            for key, (seconds, calls) in sorted(systems.items(), key=lambda item: -item[1][0]):
                print(
                    f"  {key:48s} {seconds * 1e3:6.1f} ms  {calls:5.0f} calls  "
                    f"{seconds / calls * 1e6:6.1f} us/call"
                )
    if arguments.variants:
        print()
        variants()


if __name__ == "__main__":
    main()
