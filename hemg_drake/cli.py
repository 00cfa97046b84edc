"""hemg-drake: demonstrate, learn and reproduce teleoperated tasks in Drake.

Sub-commands import their modules lazily so that ``hemg-drake --help`` is instant.
"""

import argparse
import sys
from pathlib import Path


def _demo(args):
    from hemg_drake.diagrams.arm_demo import run_arm_demo

    replay = run_arm_demo(out_dir=Path(args.out), duration=args.duration)
    print(f"wrote {replay}")


def _demonstrate(args):
    from hemg_drake.diagrams.demonstration import record_demonstrations
    from hemg_drake.scenario import load_scenario

    scenario = load_scenario(args.scenario)
    changes = {}
    if args.demos is not None:
        changes["num_demonstrations"] = args.demos
    if args.duration is not None:
        changes["duration"] = args.duration
    scenario = scenario.replaced(source="--demos/--duration", **changes)
    print(
        f"{scenario.task}: {scenario.num_demonstrations} demonstrations of "
        f"{scenario.duration:g} s into {args.out}"
    )
    for path in record_demonstrations(scenario, args.out, progress=print):
        print(f"wrote {path}")


def _emg_figure(args):
    import numpy as np

    from hemg_drake.emg.sources import MYO_RATE, load_emg_recording, synthesize_emg
    from hemg_drake.viz.figures import plot_emg_envelopes, save_figure

    if args.input:
        samples = load_emg_recording(args.input)
    else:
        if not args.duration * MYO_RATE >= 1:
            raise ValueError(f"--duration must be at least one sample (5 ms), got {args.duration}")
        # Two contractions rising from rest and relaxing, 2.5 s each, then rest.
        time = np.arange(int(args.duration * MYO_RATE)) / MYO_RATE
        activation = 0.05 + 0.9 * np.clip(np.sin(np.pi * time / 2.5), 0.0, None) ** 2
        samples = synthesize_emg(activation, args.seed)
    figure = plot_emg_envelopes(samples, args.windows, per_channel=args.per_channel)
    save_figure(figure, args.output)
    print(f"wrote {args.output}")


def build_parser():
    parser = argparse.ArgumentParser(prog="hemg-drake", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)

    demo = commands.add_parser("demo", help="run the main job (make demo)")
    demo.add_argument("--out", default="runs/demo", help="output folder")
    demo.add_argument("--duration", type=float, default=6.0, help="simulated seconds")
    demo.set_defaults(func=_demo)

    demonstrate = commands.add_parser(
        "demonstrate",
        help="record teleoperated demonstrations: dataset.npz, HTML replays, a plot",
    )
    demonstrate.add_argument("scenario", help="scenario YAML file (see scenarios/)")
    demonstrate.add_argument("--out", required=True, help="output folder, e.g. runs/pin/")
    demonstrate.add_argument("--demos", type=int, help="number of demonstrations C")
    demonstrate.add_argument("--duration", type=float, help="seconds per demonstration")
    demonstrate.set_defaults(func=_demonstrate)

    emg = commands.add_parser(
        "emg-figure", help="Fig. 6: summed sEMG and its moving-RMS envelopes"
    )
    emg.add_argument(
        "input", nargs="?", help="recording (CSV: 8 integer columns; or NPZ); synthetic if omitted"
    )
    emg.add_argument("--windows", type=int, nargs="+", default=[10, 20, 30], help="L_win values")
    emg.add_argument("--per-channel", action="store_true", help="per-channel RMS summed")
    emg.add_argument("--seed", type=int, default=0, help="seed of the synthetic recording")
    emg.add_argument(
        "--duration", type=float, default=10.0, help="synthetic recording length (s)"
    )
    emg.add_argument("-o", "--output", default="fig6.png", help="image file (.png, .svg, .pdf)")
    emg.set_defaults(func=_emg_figure)

    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except (ValueError, FileNotFoundError) as error:
        # Bad input is reported in one line, not as a traceback.
        print(f"hemg-drake {args.command}: error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
