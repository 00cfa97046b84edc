"""Link loss on the cotter pin (docs/studies.md, "Shared control"): the master-to-slave link
drops during the pull and does not come back; per assist mode and seed, does the pin still
come out (the model completing the phase alone) and where does the tool end.

    python benchmarks/bench_assist_link.py --model runs/assist_model/cotter_pin/model.npz
"""

import argparse
import time

from hemg_drake.diagrams.demonstration import build_demonstration_diagram, run_demonstration
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.sweep.trial import demonstration_metrics


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", required=True)
    parser.add_argument("--delay-ms", type=int, default=100)
    parser.add_argument("--gap-start", type=float, default=0.8)
    parser.add_argument("--seeds", type=int, nargs="+", default=[5001, 5101, 5201])
    args = parser.parse_args()
    base = [
        "num_demonstrations=1", "feedback.passivity=tdpa", f"assist.model={args.model}",
        f"mapping.delay_steps={args.delay_ms}", f"feedback.delay_steps={args.delay_ms}",
        f"assist.gap_start={args.gap_start}", "assist.gap_duration=10.0",
        "assist.link_timeout=0.2",
    ]  # fmt: skip
    print(f"cotter pin, {args.delay_ms} ms each way, link lost from {args.gap_start} s on")
    print("mode        seed  pin out  rise (mm)  final height (mm)  peak force (N)  cpu (s)")
    for mode in ("none", "fixed", "confidence", "emg"):
        extra = [f"assist.mode={mode}"] + (["assist.guidance_stiffness=1000"] if mode != "none" else [])
        scenario = load_scenario(shipped_scenario("cotter_pin"), overrides=base + extra)
        built = build_demonstration_diagram(scenario)
        for seed in args.seeds:
            start = time.process_time()
            demo = run_demonstration(built, seed)
            cpu = time.process_time() - start
            metrics = demonstration_metrics(scenario, [demo])
            rise = 1e3 * (demo.p_WE[:, 2].max() - demo.p_WE[0, 2])
            final = 1e3 * (demo.p_WE[-1, 2] - demo.p_WE[0, 2])
            print(f"{mode:10s}  {seed}  {metrics['pin_out']:.0f}        {rise:6.1f}     "
                  f"{final:6.1f}             {metrics['contact_force_peak_n']:5.1f}"
                  f"           {cpu:.1f}", flush=True)  # fmt: skip
        del built
    print("rise: the tool's highest point above its start; the pin is out at 80 mm")


if __name__ == "__main__":
    main()
