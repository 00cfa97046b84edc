"""Out-of-sample evaluation of the whole pipeline: demonstrate, learn, reproduce, then score
against fresh demonstrations on evaluation seeds that no setting was chosen on.

The seeds come from ``hemg_drake/data/seeds.yaml``: each run is a pair (training seed s,
fresh seed t). The scenario's C demonstrations are recorded from s .. s + C - 1, the HSMM is
learnt from them, and the task is reproduced (the scenario's tracker, or each of
``--trackers``); the reproduction is scored against C_test = 4 fresh demonstrations from
t .. t + 3 (``pipeline.demonstrate_heldout``, ``evaluation.task_metrics``). Every figure is
printed out of sample first, then in sample (against the training demonstrations) in
brackets, then the floor: the fresh demonstrations' own median leave-one-out figure (each
against the mean of the other three). The benchmark refuses a tuning seed; ``--tuning``
runs the tuning pairs instead (where settings are chosen) and refuses an evaluation seed.

Goals per run (issue 15), out of sample and in sample:

- the task's success checks (pin out along its axis, no overshoot; three strokes in shape
  and in place);
- position RMSE after DTW <= 2.2 mm and velocity RMSE after DTW <= 0.0788 m/s (Table II's);
- time-normalised position RMSE no worse than the demonstrations' own median leave-one-out.

    .venv/bin/python benchmarks/bench_heldout.py [--tasks ...] [--runs 5] [--tuning]
        [--trackers gmr lqr] [--set KEY=VALUE ...] [--json out.json]
"""

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from hemg_drake.analysis.seeds import check_seeds, run_seeds, seed_sets
from hemg_drake.pipeline import demonstrate, demonstrate_heldout, learn, reproduce
from hemg_drake.scenario import load_scenario, shipped_scenario

NUM_FRESH = 4
GOAL_DTW_M, GOAL_DTW_VELOCITY = 0.0022, 0.0788


def quiet(_line):
    pass


def run_scenario(task, seed, fresh, overrides=(), kind="evaluation", count=NUM_FRESH):
    """The shipped scenario for one (training, fresh) pair, its seeds checked as ``kind``;
    ``count`` fresh demonstrations."""
    scenario = load_scenario(shipped_scenario(task), overrides=[
        *overrides, f"seed={seed}", f"reproduction.heldout_seed={fresh}",
        f"reproduction.num_heldout={count}",
    ])  # fmt: skip
    check_seeds(scenario.seeds() + run_seeds(fresh, count), kind,
                what=f"{task} run ({seed}, {fresh})")  # fmt: skip
    return scenario


def evaluate(scenario, folder, trackers=None, variants=("",)):
    """Metrics of each variant and tracker (default: the scenario's) for one run: dict
    "VARIANT TRACKER" -> metrics. A variant is comma-separated learning.* / reproduction.*
    overrides, learnt and reproduced from the same demonstrations ("": as shipped)."""
    run = Path(folder) / f"{scenario.task}_{scenario.seed}"
    demonstrate(scenario, run, replays=False, progress=quiet)
    heldout = demonstrate_heldout(scenario, run, progress=quiet)
    results = {}
    for v, variant in enumerate(variants):
        overrides = [o for o in variant.split(",") if o]
        learn(run, overrides=overrides, progress=quiet)
        for tracker in trackers or [scenario.replaced(overrides).reproduction.tracker]:
            name = f"{variant} {tracker}".strip()
            results[name] = reproduce(
                run, overrides=[*overrides, f"reproduction.tracker={tracker}"],
                out_dir=run / f"{v}_{tracker}", replay=False, heldout=heldout, progress=quiet,
            )  # fmt: skip
    return results


def goals(lead, floor):
    """Which goals a set of lead figures meets (dict name -> bool)."""
    return {
        "success": bool(lead["success"]),
        "after DTW": lead["spatial_position_rmse_m"] <= GOAL_DTW_M,
        "velocity after DTW": lead["spatial_velocity_rmse_m_per_s"] <= GOAL_DTW_VELOCITY,
        "within the floor": lead["position_rmse_m"] <= floor["position_rmse_m"],
    }


def in_sample_floor(m):
    from hemg_drake.evaluation import leave_one_out_floor

    return leave_one_out_floor(m)


def row(seed, fresh, tracker, m):
    scores = m["scores"]
    out, inside, floor = scores["out_of_sample"], scores["in_sample"], scores["floor"]

    def cell(key, scale=1e3, digits=2):
        return (f"{scale * out[key]:.{digits}f} ({scale * inside[key]:.{digits}f}) "
                f"[{scale * floor[key]:.{digits}f}]")  # fmt: skip

    cells = [f"{seed} / {fresh}", tracker, cell("spatial_position_rmse_m"),
             cell("position_rmse_m", digits=1), cell("spatial_velocity_rmse_m_per_s", 1, 3),
             cell("timing_error_s", 1, 2)]  # fmt: skip
    o = m["out_of_sample"]
    if "pin_out" in m:
        cells += [str(m["pin_out"]), f"{1e3 * o['overshoot_m']:+.0f}",
                  f"{o['pull_direction_error_deg']:.1f}"]  # fmt: skip
    else:
        shapes = o["stroke_shape_error_m"]
        cells += [str(m["strokes"]),
                  " / ".join("-" if e is None else f"{1e3 * e:.1f}" for e in shapes)]  # fmt: skip
    met_out = goals(out, floor)
    met_in = goals(inside, in_sample_floor(m))
    cells += [f"{out['success']} ({inside['success']})",
              f"{sum(met_out.values())}/4 ({sum(met_in.values())}/4)"]  # fmt: skip
    return "| " + " | ".join(cells) + " |", met_out, met_in


_METRICS = ("| seeds (train / fresh) | tracker | pos after DTW mm | time-norm. pos RMSE mm "
            "| vel after DTW m/s | timing s |")
HEADERS = {
    "cotter_pin": _METRICS + " pin out | overshoot mm | pull axis deg | success | goals met |",
    "drawing": _METRICS + " strokes | shape errors mm | success | goals met |",
}
LEGEND = ("out of sample (in sample) [floor: the fresh demonstrations' own median "
          "leave-one-out]; task cells against the fresh demonstrations")


def pairs(task, kind, count):
    runs = seed_sets()[kind]["runs"][task]
    return runs[:count] if count else runs


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=["cotter_pin", "drawing"])
    parser.add_argument("--runs", type=int, default=0, help="the first N pairs (default: all)")
    parser.add_argument("--tuning", action="store_true",
                        help="the tuning pairs (choose settings here); default: evaluation")
    parser.add_argument("--seeds", type=int, nargs=2, action="append", metavar=("S", "T"),
                        help="a run of your own: training seed S, fresh seed T (checked)")
    parser.add_argument("--trackers", nargs="+", choices=["gmr", "lqr"])
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--variants", nargs="+", default=[""], metavar="K=V[,K=V]",
                        help="learning/reproduction settings compared on the same "
                        "demonstrations ('' for the shipped ones)")
    parser.add_argument("--fresh", type=int, default=NUM_FRESH,
                        help=f"fresh demonstrations per run (default {NUM_FRESH}; at least 2)")
    parser.add_argument("--json", help="also write every metric to this file")
    args = parser.parse_args(argv)
    if args.fresh < 2:
        parser.error("--fresh must be at least 2 (their own leave-one-out is the floor)")
    kind = "tuning" if args.tuning else "evaluation"
    plans = {task: args.seeds or pairs(task, kind, args.runs) for task in args.tasks}
    try:  # every run's seeds checked before anything is simulated
        scenarios = {task: [run_scenario(task, s, t, args.set, kind, args.fresh)
                            for s, t in runs]
                     for task, runs in plans.items()}  # fmt: skip
    except ValueError as error:
        print(f"bench_heldout: {error}", file=sys.stderr)
        return 2
    everything = {}
    with tempfile.TemporaryDirectory() as folder:
        for task, runs in scenarios.items():
            print(f"\n{task}, {kind} seeds; {LEGEND}" + (f"; --set {args.set}" if args.set else ""))
            print(HEADERS[task])
            print("|" + "---|" * (HEADERS[task].count("|") - 1))
            count = {}
            for scenario in runs:
                start = time.perf_counter()
                fresh = scenario.reproduction.heldout_seed
                results = evaluate(scenario, folder, args.trackers, args.variants)
                everything[f"{task} {scenario.seed}"] = results
                for tracker, metrics in results.items():
                    line, met_out, met_in = row(scenario.seed, fresh, tracker, metrics)
                    count.setdefault(tracker, {"out": [0, 0], "in": [0, 0]})
                    print(line, flush=True)
                    for key, met in (("out", met_out), ("in", met_in)):
                        count[tracker][key][0] += all(met.values())
                        count[tracker][key][1] += 1
                print(f"<!-- {task} {scenario.seed}: {time.perf_counter() - start:.0f} s -->",
                      flush=True)  # fmt: skip
            for name, c in count.items():
                print(f"{name}: every goal met out of sample {c['out'][0]}/{c['out'][1]}, "
                      f"in sample {c['in'][0]}/{c['in'][1]}")
    if args.json:
        Path(args.json).write_text(json.dumps(everything, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
