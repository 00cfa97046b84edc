"""hemg-drake: demonstrate, learn and reproduce teleoperated tasks in Drake.

Every mistake is answered in one line on stderr with exit status 2 (a bad value, a missing
or unwritable file); Ctrl-C stops with one line and exit status 130 (SIGTERM: 143), leaving
no partial output. Sub-commands import their modules lazily so that ``hemg-drake --help``
is instant.
"""

import argparse
import math
import os
import signal
import sys
import threading
import warnings

from hemg_drake.commands import (
    demo_command,
    demonstrate_command,
    emg_figure_command,
    export_command,
    import_robomimic_command,
    learn_command,
    repair_command,
    reproduce_command,
    stability_command,
    sweep_command,
    takes_command,
    teleop_command,
)

SET_HELP = (
    "override a scenario key, in YAML value syntax (repeatable), e.g. --set emg.k_max=150 "
    "--set scene.position=[0.65,-0.80,0.12]"
)
# learn and reproduce read some sections of the dataset's scenario only (commands.READS).
LEARN_SET_HELP = (
    "override a learning key of the dataset's scenario, in YAML value syntax (repeatable), "
    "e.g. --set learning.num_states=6 --set learning.init=kmeans"
)
REPRODUCE_SET_HELP = (
    "override a reproduction or scene key of the dataset's scenario, in YAML value syntax "
    "(repeatable), e.g. --set reproduction.tracker=lqr --set scene.yaw_deg=20"
)
# Longest demonstration (s), as the scenario's check has it.
MAX_DURATION = 600.0
# The extra that installs each optional package a command may need (pyproject.toml).
OPTIONAL_EXTRAS = {
    "h5py": "export", "pyarrow": "lerobot", "ray": "ray", "pyOpenHaptics": "touchx", "pyomyo": "myo",
}  # fmt: skip
# emg-figure's synthetic recording: at most this long (s); a longer one takes minutes and
# gigabytes to plot for no more insight.
MAX_EMG_FIGURE_DURATION = 600.0
# Drake's RandomGenerator takes 32-bit seeds (2**32 draws what 0 draws).
MAX_SEED = 2**32 - 1
MAX_PORT = 65535
# EM iterations at most (the scenario's learning.n_iter has the same bound).
MAX_ITERATIONS = 1000


def _int_at_least(name, minimum, maximum=None):
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a whole number, got {text!r}")
        if value < minimum:
            bound = "must not be negative" if minimum == 0 else f"must be at least {minimum}"
            raise argparse.ArgumentTypeError(f"{name} {bound}, got {value}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"{name} must be at most {maximum}, got {value}")
        return value

    return parse


def _positive_int(name, maximum=None):
    return _int_at_least(name, 1, maximum)


def _non_negative_int(name, maximum=None):
    return _int_at_least(name, 0, maximum)


def _finite_float(name, *, positive=False, maximum=math.inf):
    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}")
        if not math.isfinite(value) or (positive and value <= 0) or value > maximum:
            bound = f" and at most {maximum:g}" if math.isfinite(maximum) else ""
            kind = "a positive number" if positive else "a finite number"
            raise argparse.ArgumentTypeError(f"{name} must be {kind}{bound}, got {text}")
        return value

    return parse


def _version():
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("hemg-drake")
    except PackageNotFoundError:
        import hemg_drake

        return hemg_drake.__version__


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (``--help`` shows the usage)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


class _Formatter(argparse.ArgumentDefaultsHelpFormatter):
    """Show defaults, but not for flags and options whose default is None."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False or action.default == []:
            return action.help
        return super()._get_help_string(action)


def build_parser():
    parser = _Parser(
        prog="hemg-drake",
        description="Demonstrate, learn and reproduce teleoperated tasks in Drake.",
        formatter_class=_Formatter,
    )
    parser.add_argument("--version", action="version", version=f"hemg-drake {_version()}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name, help):
        return commands.add_parser(name, help=help, description=help, formatter_class=_Formatter)

    def add_set(sub, help=SET_HELP):
        sub.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help=help)

    demo = command("demo", "the main job (make demo): demonstrate, learn, reproduce both tasks")
    demo.add_argument("--out", default="runs", help="output folder (one sub-folder per task)")
    demo.add_argument(
        "--tasks", nargs="+", default=["cotter_pin", "drawing"],
        choices=["cotter_pin", "drawing"], help="tasks to run",
    )  # fmt: skip
    demo.add_argument("--no-replay", action="store_true", help="write no HTML replays")
    demo.add_argument(
        "--no-placements", action="store_true",
        help="skip the demonstrations at several placements and the reproduction at a new one "
        "(TASK/placements/, about 25 s of the demo's 50 s)",
    )  # fmt: skip
    add_set(demo)
    demo.set_defaults(func=demo_command)

    demonstrate = command(
        "demonstrate", "record teleoperated demonstrations: dataset.npz, HTML replays, plots"
    )
    demonstrate.add_argument(
        "scenario", help="scenario YAML file, or a shipped one: cotter_pin, drawing"
    )
    demonstrate.add_argument("--out", required=True, help="output folder, e.g. runs/pin/")
    demonstrate.add_argument(
        "--demos", type=_positive_int("--demos"),
        help="number of demonstrations C (default: the scenario's num_demonstrations)",
    )
    demonstrate.add_argument(
        "--duration", type=_finite_float("--duration", positive=True, maximum=MAX_DURATION),
        help="seconds per demonstration (default: the scenario's duration)",
    )  # fmt: skip
    demonstrate.add_argument(
        "--seed", type=_non_negative_int("--seed", MAX_SEED),
        help="seed of the first demonstration (default: the scenario's seed)",
    )
    demonstrate.add_argument("--no-replay", action="store_true", help="write no HTML replays")
    add_set(demonstrate)
    demonstrate.set_defaults(func=demonstrate_command)

    learn = command("learn", "fit the HSMM of a run folder's dataset")
    learn.add_argument("run", help="run folder holding dataset.npz, e.g. runs/cotter_pin/")
    learn.add_argument(
        "--iterations", type=_positive_int("--iterations", MAX_ITERATIONS),
        help="EM iterations at most (default: the scenario's learning.n_iter)",
    )  # fmt: skip
    add_set(learn, LEARN_SET_HELP)
    learn.set_defaults(func=learn_command)

    reproduce = command("reproduce", "simulate the learnt task; write replay, figures, metrics")
    reproduce.add_argument("run", help="run folder holding dataset.npz and model.npz")
    reproduce.add_argument(
        "--start-offset", type=_finite_float("--start-offset"), nargs=3,
        default=[0.0, 0.0, 0.0], metavar=("DX", "DY", "DZ"),
        help="start this far from the demonstrations' start (m, scene frame)",
    )  # fmt: skip
    reproduce.add_argument(
        "--weighting", choices=["temporal", "spatial", "forward"],
        help="HSMM state weighting (default: the scenario's reproduction.weighting)",
    )  # fmt: skip
    reproduce.add_argument(
        "--restoring-gain", type=_finite_float("--restoring-gain"), metavar="KAPPA",
        help="tracker gmr only: pull back to the demonstrated path at this rate (1/s; 0: "
        "none; default: the scenario's reproduction.restoring_gain; the lqr tracker returns "
        "to the path by re-planning and ignores it)",
    )  # fmt: skip
    reproduce.add_argument(
        "--tracker", choices=["gmr", "lqr"],
        help="gmr: the paper's eqs. 15-18; lqr: an LQR tracking the HSMM's states from the "
        "measured tool point (default: the scenario's reproduction.tracker)",
    )  # fmt: skip
    reproduce.add_argument("--out", help="output folder (default: the run folder)")
    reproduce.add_argument(
        "--heldout", metavar="FOLDER",
        help="a run folder of fresh demonstrations of the task (other seeds): the metrics "
        "lead with the reproduction scored against them (out of sample)",
    )  # fmt: skip
    reproduce.add_argument("--no-replay", action="store_true", help="write no HTML replay")
    add_set(reproduce, REPRODUCE_SET_HELP)
    reproduce.set_defaults(func=reproduce_command)

    emg = command("emg-figure", "Fig. 6: summed sEMG and its moving-RMS envelopes")
    emg.add_argument(
        "input", nargs="?",
        help="recording (CSV: 8 integer columns; or NPZ); a synthetic one if omitted",
    )  # fmt: skip
    emg.add_argument(
        "--windows", type=_positive_int("--windows"), nargs="+", default=[10, 20, 30],
        help="L_win values (samples)",
    )  # fmt: skip
    emg.add_argument("--per-channel", action="store_true", help="per-channel RMS summed")
    emg.add_argument(
        "--seed", type=_non_negative_int("--seed", MAX_SEED), default=0,
        help="seed of the synthetic recording",
    )  # fmt: skip
    emg.add_argument(
        "--duration",
        type=_finite_float("--duration", positive=True, maximum=MAX_EMG_FIGURE_DURATION),
        default=10.0, help="synthetic recording length (s)",
    )  # fmt: skip
    emg.add_argument("-o", "--output", default="fig6.png", help="image file (.png, .svg, .pdf)")
    emg.set_defaults(func=emg_figure_command)
    export = command(
        "export", "write a run's demonstrations in another format (robomimic HDF5, LeRobot v3.0)"
    )
    export.add_argument("run", help="run folder holding dataset.npz (or a dataset file)")
    export.add_argument(
        "--format", choices=["robomimic", "lerobot"], default="robomimic",
        help="robomimic: its HDF5 layout (data/demo_i/obs, actions; needs h5py), a file; "
        "lerobot: a LeRobot v3.0 dataset folder (meta/, data/; needs pyarrow), with HSMM "
        "states when the run folder holds a model learnt from its dataset",
    )  # fmt: skip
    export.add_argument(
        "output", help="file (robomimic, e.g. runs/pin/demos.hdf5) or folder (lerobot, e.g. "
        "runs/pin_lerobot/: new, empty or an earlier lerobot export) to write",
    )  # fmt: skip
    export.set_defaults(func=export_command)
    imports = command("import", "read demonstrations exported with export into a run folder")
    imports.add_argument("input", help="robomimic HDF5 file written by hemg-drake export")
    imports.add_argument(
        "--format", choices=["robomimic"], default="robomimic", help="the file's format"
    )
    imports.add_argument("--out", required=True, help="run folder to write dataset.npz into")
    imports.set_defaults(func=import_robomimic_command)

    repair = command(
        "repair", "rebuild a run folder's manifest from the files there (changes nothing else)"
    )
    repair.add_argument("run", help="run folder, e.g. runs/pin/")
    repair.set_defaults(func=repair_command)

    teleop = command(
        "teleop", "drive the arm yourself in the browser (Meshcat); append the take to a dataset"
    )
    teleop.add_argument("scenario", help="scenario YAML file, or a shipped one: cotter_pin, drawing")
    teleop.add_argument("--out", required=True, help="run folder; the take joins its dataset.npz")
    teleop.add_argument(
        "--port", type=_non_negative_int("--port", MAX_PORT), default=7000,
        help="Meshcat's port on localhost (0: a free one)",
    )  # fmt: skip
    teleop.add_argument(
        "--duration", type=_finite_float("--duration", positive=True),
        help="end the take after this many simulated seconds (default: none; End take, "
        "Escape or a closed page ends it)",
    )  # fmt: skip
    teleop.add_argument(
        "--replay-inputs", metavar="LOG.npz",
        help="re-drive a take headless from its inputs log (inputs_<c>.npz) (default: a "
        "live take in the browser)",
    )  # fmt: skip
    teleop.add_argument(
        "--takes", type=_positive_int("--takes"), default=1,
        help="keep this many takes in a row on the same page (each started with Enter)",
    )  # fmt: skip
    teleop.add_argument("--no-replay", action="store_true", help="write no HTML replay")
    teleop.add_argument(
        "--no-wait", action="store_true",
        help="for scripts: start each take at once and keep it when it ends (default: Enter "
        "starts a take at the page; K keeps it, D discards it)",
    )  # fmt: skip
    add_set(teleop)
    teleop.set_defaults(func=teleop_command)

    takes = command("takes", "list the takes (demonstrations) of a run folder, or remove one")
    takes.add_argument("run", help="run folder, e.g. runs/my_pin/")
    takes.add_argument(
        "--remove", type=_positive_int("--remove"), metavar="K",
        help="remove take K (the later ones are renumbered; the model and reproductions made "
        "from the older dataset go with it)",
    )  # fmt: skip
    takes.set_defaults(func=takes_command)

    stability = command(
        "stability", "the teleoperation loop's stability against delay, by linearisation"
    )
    stability.add_argument("scenario", help="scenario YAML file, or a shipped one: cotter_pin, drawing")
    stability.add_argument(
        "--delays", type=_finite_float("--delays"), nargs="+",
        default=[0, 5, 10, 15, 20, 25, 50, 100, 150, 200], metavar="MS",
        help="one-way delays (ms, each way; whole master samples)",
    )  # fmt: skip
    stability.add_argument(
        "--gains", type=_finite_float("--gains", positive=True), nargs="+", metavar="K",
        help="the PD's K held during the hold (default: the scenario's emg.k_min and k_max)",
    )  # fmt: skip
    stability.add_argument("-o", "--output", help="also draw the figure (.png, .svg, .pdf)")
    add_set(stability)
    stability.set_defaults(func=stability_command)

    sweep = command("sweep", "run a sweep file's trials on all cores (or Ray); table + figure")
    sweep.add_argument(
        "sweep", help="sweep YAML file, or a shipped one (hemg_drake/sweeps/): example_delay, "
        "delay, delay_drawing, emg_cotter_pin, emg_drawing, learning",
    )  # fmt: skip
    sweep.add_argument("--out", required=True, help="output folder, e.g. runs/sweep/")
    sweep.add_argument(
        "--backend", choices=["local", "ray"], default="local",
        help="local: a process pool on this machine; ray: one Ray task per trial",
    )  # fmt: skip
    sweep.add_argument(
        "--workers", type=_positive_int("--workers"),
        help="parallel trials (default: all cores)",
    )  # fmt: skip
    sweep.add_argument("--address", help="Ray cluster to join (ray start --head prints it)")
    sweep.add_argument("--resume", action="store_true", help="skip the trials already done")
    sweep.set_defaults(func=sweep_command)
    return parser


def _one_line(error):
    if isinstance(error, OSError) and error.filename is not None:
        reason = error.strerror or type(error).__name__
        return f"{error.filename}: {reason}"
    text = str(error).strip() or type(error).__name__
    return text.splitlines()[0]


class Terminated(BaseException):
    """SIGTERM, raised where the command is, so that it unwinds as Ctrl-C does."""


# Retry delay (s) of a signal that arrived inside LLVM's JIT (numba compiling), and the
# retries pending.
SIGNAL_RETRY = 0.02
_RETRIES = []
# The exception each handled signal raised. pybind11 turns an exception raised while it
# converts a C++ call's arguments (numpy calls back into Python, where the handler runs)
# into a TypeError "incompatible function arguments": main() reads the signal from here.
_RAISED = []


def _in_llvm(frame):
    """Whether ``frame`` or a caller runs llvmlite's code (numba compiling with LLVM)."""
    while frame is not None:
        if frame.f_globals.get("__name__", "").startswith("llvmlite."):
            return True
        frame = frame.f_back
    return False


def _raising(exception):
    """A signal handler raising ``exception`` where the command is.

    Inside llvmlite, LLVM may be running a Python callback through ctypes (its object cache,
    while numba compiles a kernel): an exception raised there is printed as "Exception
    ignored" and dropped, and numba then fails with a traceback of its own (or the command
    runs on as if never interrupted). There the signal is sent again a moment later, until
    it arrives outside llvmlite.
    """

    def handle(signum, frame):
        if _in_llvm(frame):
            retry = threading.Timer(SIGNAL_RETRY, os.kill, (os.getpid(), signum))
            retry.daemon = True
            retry.start()
            _RETRIES.append(retry)  # cancelled if the command ends first
            return
        _RAISED.append(exception)
        raise exception()

    return handle


def _commands_list(parser):
    """The usage line and one line per command with its help (``hemg-drake`` alone)."""
    (commands,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    width = max(len(c.dest) for c in commands._choices_actions)
    lines = [f"  {c.dest:<{width}}  {c.help}" for c in commands._choices_actions]
    return parser.format_usage() + "commands:\n" + "\n".join(lines) + "\n"


def _missing_package(error):
    """One sentence for an ImportError: the optional package and the extra that installs it
    (pyproject.toml), else the error's own first line."""
    name = (error.name or "").split(".")[0]
    extra = OPTIONAL_EXTRAS.get(name)
    if extra:
        return f"needs the optional package {name}: pip install 'hemg-drake[{extra}]'"
    if error.name:
        return f"needs the package {error.name}, which is not installed"
    return _one_line(error)


def main(argv=None):
    parser = build_parser()
    if not (sys.argv[1:] if argv is None else argv):
        sys.stderr.write(_commands_list(parser))
        return 2
    args = parser.parse_args(argv)
    previous = {
        signal.SIGINT: signal.signal(signal.SIGINT, _raising(KeyboardInterrupt)),
        signal.SIGTERM: signal.signal(signal.SIGTERM, _raising(Terminated)),
    }

    def one_line_warning(message, category, *_):  # a warning, like an error, in one line
        print(f"hemg-drake {args.command}: warning: {_one_line(message)}", file=sys.stderr)

    _RAISED.clear()
    try:
        with warnings.catch_warnings():
            warnings.showwarning = one_line_warning
            try:
                status = args.func(args)
            except Exception as error:
                if _RAISED:  # the signal, reported by pybind11 as another error
                    raise _RAISED[-1]() from error
                raise
    except KeyboardInterrupt as error:
        # A command may say what it kept (sweep: its finished trials) in the error's args.
        kept = str(error) or "no partial output kept"
        print(f"hemg-drake {args.command}: interrupted; {kept}", file=sys.stderr)
        return 130
    except Terminated as error:
        kept = str(error) or "no partial output kept"
        print(f"hemg-drake {args.command}: terminated; {kept}", file=sys.stderr)
        return 143
    except ImportError as error:
        # An optional dependency (pyproject.toml's extras) that this install lacks.
        print(f"hemg-drake {args.command}: error: {_missing_package(error)}", file=sys.stderr)
        return 2
    except (ValueError, OSError) as error:
        # Bad input and unwritable or missing files are reported in one line.
        print(f"hemg-drake {args.command}: error: {_one_line(error)}", file=sys.stderr)
        return 2
    finally:
        while _RETRIES:
            _RETRIES.pop().cancel()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    return status or 0  # a command's own status (sweep: 1 when a trial failed)


if __name__ == "__main__":
    sys.exit(main())
