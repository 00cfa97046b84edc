"""hemg-drake: demonstrate, learn and reproduce teleoperated tasks in Drake.

Sub-commands import their modules lazily so that ``hemg-drake --help`` is instant.
"""

import argparse
import sys
from pathlib import Path


def _demo(args):
    from hemg_drake.diagrams.arm_demo import run_arm_demo

    replay = run_arm_demo(out_dir=Path(args.out))
    print(f"wrote {replay}")


def build_parser():
    parser = argparse.ArgumentParser(prog="hemg-drake", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)

    demo = commands.add_parser("demo", help="run the main job (make demo)")
    demo.add_argument("--out", default="runs/demo", help="output folder")
    demo.set_defaults(func=_demo)

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
