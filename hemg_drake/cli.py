"""hemg-drake: demonstrate, learn and reproduce teleoperated tasks in Drake.

Sub-commands import their modules lazily so that ``hemg-drake --help`` is instant.
"""

import argparse
import sys


def _demo(args):
    from hemg_drake.pipeline import run_demo

    run_demo(args.out, tasks=args.tasks, replays=not args.no_replay)


def _learn(args):
    from hemg_drake.pipeline import learn

    learn(args.run, n_iter=args.iterations)


def _reproduce(args):
    from hemg_drake.pipeline import DEFAULT_WEIGHTING, RESTORING_GAIN, reproduce

    reproduce(
        args.run,
        start_offset=args.start_offset,
        weighting=args.weighting or DEFAULT_WEIGHTING,
        restoring_gain=RESTORING_GAIN if args.restoring_gain is None else args.restoring_gain,
        out_dir=args.out,
        replay=not args.no_replay,
    )


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

    demo = commands.add_parser(
        "demo", help="the main job (make demo): demonstrate, learn, reproduce both tasks"
    )
    demo.add_argument("--out", default="runs", help="output folder (one sub-folder per task)")
    demo.add_argument(
        "--tasks", nargs="+", default=["cotter_pin", "drawing"], help="tasks to run"
    )
    demo.add_argument("--no-replay", action="store_true", help="write no HTML replays")
    demo.set_defaults(func=_demo)

    learn = commands.add_parser("learn", help="fit the HSMM of a run folder's dataset")
    learn.add_argument("run", help="run folder holding dataset.npz, e.g. runs/cotter_pin/")
    learn.add_argument("--iterations", type=int, default=100, help="EM iterations at most")
    learn.set_defaults(func=_learn)

    reproduce = commands.add_parser(
        "reproduce", help="simulate the learnt task; write replay, figures, metrics"
    )
    reproduce.add_argument("run", help="run folder holding dataset.npz and model.npz")
    reproduce.add_argument(
        "--start-offset", type=float, nargs=3, default=[0.0, 0.0, 0.0],
        metavar=("DX", "DY", "DZ"), help="start this far from the demonstrations' start (m)",
    )  # fmt: skip
    reproduce.add_argument(
        "--weighting", choices=["temporal", "spatial", "forward"],
        help="HSMM state weighting (default: the pipeline's, temporal)",
    )  # fmt: skip
    reproduce.add_argument(
        "--restoring-gain", type=float, metavar="KAPPA",
        help="pull back to the demonstrated path at this rate (1/s; 0: none; default 2)",
    )  # fmt: skip
    reproduce.add_argument("--out", help="output folder (default: the run folder)")
    reproduce.add_argument("--no-replay", action="store_true", help="write no HTML replay")
    reproduce.set_defaults(func=_reproduce)

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
