"""The assist's own signals on one demonstration per mode (docs/studies.md, "Shared control").

For each assist mode: the mean weight w (over the run and over the pull, where the operator
works against the pin), the mean confidence, how late the online phase (the intent
estimator's, from the delayed commands) becomes the offline one (the model's smoothed
state sequence of the recorded tool motion, ``HSMM.predict_states``), mean over the
transitions (negative: early), and the passivity observer's least energy. CPU seconds per run.

    python benchmarks/bench_assist.py --model runs/assist_model/cotter_pin/model.npz \
        --delay-ms 250 --seed 5001
"""

import argparse
import time

import numpy as np

from hemg_drake.analysis.effort import phase_lags
from hemg_drake.diagrams.assist import ASSIST_LOGGED
from hemg_drake.diagrams.built import make_simulator
from hemg_drake.diagrams.demonstration import (
    build_demonstration_diagram,
    demonstration_from_logs,
    initial_context,
)
from hemg_drake.diagrams.log import split_log
from hemg_drake.learning.demos import observations
from hemg_drake.learning.tphsmm import load_model
from hemg_drake.scenario import load_scenario, shipped_scenario


def run(scenario, seed):
    built = build_demonstration_diagram(scenario)
    simulator, duration = make_simulator(built, None)
    simulator.reset_context(initial_context(built, seed))
    simulator.Initialize()
    feedback = built.diagram.GetSubsystemByName("force_feedback")
    context = simulator.get_context()
    start, least = time.process_time(), np.inf
    for t in np.arange(0.01, duration + 1e-9, 0.01):
        simulator.AdvanceTo(t)
        least = min(least, feedback.energy(feedback.GetMyContextFromRoot(context)))
    cpu = time.process_time() - start
    demo = demonstration_from_logs(
        built.logger.FindLog(context), built.emg_logger.FindLog(context), seed
    )
    signals = None
    if built.assist_logger is not None:
        log = built.assist_logger.FindLog(context)
        signals = split_log(log, ASSIST_LOGGED)
    return demo, signals, least, cpu


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="cotter_pin")
    parser.add_argument("--model", required=True)
    parser.add_argument("--delay-ms", type=int, default=250)
    parser.add_argument("--seed", type=int, default=5001)
    parser.add_argument("--set", action="append", default=[])
    args = parser.parse_args()
    model = load_model(args.model)
    base = [
        "num_demonstrations=1", "feedback.passivity=tdpa", f"assist.model={args.model}",
        f"mapping.delay_steps={args.delay_ms}", f"feedback.delay_steps={args.delay_ms}",
        *args.set,
    ]  # fmt: skip
    print(f"{args.task}, one-way delay {args.delay_ms} ms, seed {args.seed}")
    print("mode        w mean  w pull  kappa  phase lag (s)  E min (J)  cpu (s)")
    for mode in ("fixed", "confidence", "emg"):
        scenario = load_scenario(
            shipped_scenario(args.task),
            overrides=[*base, f"assist.mode={mode}", "assist.guidance_stiffness=1000"],
        )
        demo, signals, least, cpu = run(scenario, args.seed)
        offline = model.predict_states(observations([demo])[0])
        online = signals["phase"][:, 0].astype(int)[: len(offline)]
        lags = phase_lags(demo.time, online, offline)
        w = signals["weight"][:, 0]
        pull = (demo.time >= 0.5) & (demo.time <= 2.0)
        print(f"{mode:10s}  {w.mean():.3f}   {w[pull[: len(w)]].mean():.3f}   "
              f"{signals['confidence'][:, 0].mean():.3f}  {np.nanmean(lags):.3f} "
              f"({np.isnan(lags).sum()} missed)  {least:.1e}  {cpu:.1f}")  # fmt: skip


if __name__ == "__main__":
    main()
