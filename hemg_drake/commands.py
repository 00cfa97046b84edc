"""The sub-commands of ``hemg-drake`` (:mod:`hemg_drake.cli` parses their arguments).

Each ``*_command`` takes the parsed arguments, checks its inputs and output before any
simulation and raises ``ValueError`` or ``OSError`` for a mistake (the entry point answers it
in one line). Each imports its modules when it runs, so that ``hemg-drake --help`` is instant.
"""

import os
import sys
from pathlib import Path


# The scenario keys that learn and reproduce read from the dataset's scenario (pipeline.learn:
# learning_data, fit_model; pipeline.reproduce: the placement, build_reproduction_diagram);
# a --set of any other key would do nothing, and is refused.
READS = {
    "learn": ("learning", "seed"),
    "reproduce": (
        "reproduction", "scene.position", "scene.yaw_deg", "scene.cotter_pin", "scene.drawing",
        "scene.block", "plant", "simulator", "visualization", "clik", "pd", "emg.k_min", "emg.k_max",
    ),
}  # fmt: skip


# Longest delay stability linearises (ms each way): the loop has about 10 states per ms of
# delay and its Jacobian is dense, so memory grows as the square and time as about the cube
# (measured: 200 ms 2040 states, 0.46 GB, 16 s; 400 ms 4040 states, 1 GB, 48 s of CPU).
MAX_STABILITY_DELAY_MS = 500.0


def _print(line):
    """Print, and keep working if the reader went away (``| head``)."""
    try:
        print(line, flush=True)
    except BrokenPipeError:
        # Later lines go nowhere; the job itself carries on and finishes its files.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


def check_output_folder(path):
    """Raise ValueError unless ``path`` is a writable folder or can be made one (it is not
    made here: nothing is written before the inputs are checked too).

    Checked before any simulation, so a bad ``--out`` costs nothing.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"{path}: exists and is not a folder")
    existing = path
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"{path}: cannot write there ({existing} is a file, not a folder)")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"{path}: cannot write there ({existing} is not writable)")
    return path


def check_output_file(path):
    """Raise ValueError unless a file can be written at ``path`` (not a folder)."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: is a folder; give a file name, e.g. {path / 'fig6.png'}")
    check_output_folder(path.parent if str(path.parent) else Path("."))
    return path


def _scenario_path(name):
    """A scenario file, or the name of a shipped one (``cotter_pin``, ``drawing``)."""
    from hemg_drake.scenario import TASKS, shipped_scenario

    if name in TASKS and not Path(name).exists():
        return shipped_scenario(name)
    return Path(name)


def demo_command(args):
    """``hemg-drake demo``: demonstrate, learn and reproduce each task into ``args.out``."""
    from hemg_drake.demo import run_demo

    check_output_folder(args.out)
    run_demo(
        args.out, tasks=args.tasks, overrides=args.set, replays=not args.no_replay,
        placements=not args.no_placements, progress=_print,
    )  # fmt: skip


def _with_flags(args, **keys):
    """``--set`` overrides followed by one per flag given: flag name -> scenario key."""
    overrides = list(args.set)
    for flag, key in keys.items():
        value = getattr(args, flag)
        if value is not None:
            overrides.append(f"{key}={value}")
    return overrides


def demonstrate_command(args):
    """``hemg-drake demonstrate``: record a scenario's demonstrations into a run folder."""
    from hemg_drake.pipeline import demonstrate
    from hemg_drake.scenario import load_scenario

    overrides = _with_flags(args, demos="num_demonstrations", duration="duration", seed="seed")
    scenario = load_scenario(_scenario_path(args.scenario), overrides=overrides)
    check_output_folder(args.out)
    count = scenario.num_demonstrations
    _print(
        f"{scenario.task}: {count} demonstration{'s' if count != 1 else ''} of "
        f"{scenario.duration:g} s into {args.out}"
    )
    for path in demonstrate(scenario, args.out, replays=not args.no_replay, progress=_print):
        _print(f"wrote {path}")


def learn_command(args):
    """``hemg-drake learn``: fit the HSMM of a run folder's dataset."""
    from hemg_drake.pipeline import learn
    from hemg_drake.scenario import check_overrides_read

    check_overrides_read(args.set, READS["learn"], reader="learn")
    learn(args.run, overrides=args.set, n_iter=args.iterations, progress=_print)


def reproduce_command(args):
    """``hemg-drake reproduce``: simulate the learnt task of a run folder."""
    from hemg_drake.pipeline import reproduce
    from hemg_drake.scenario import check_overrides_read

    overrides = _with_flags(
        args, weighting="reproduction.weighting", restoring_gain="reproduction.restoring_gain",
        tracker="reproduction.tracker",
    )  # fmt: skip
    check_overrides_read(overrides, READS["reproduce"], reader="reproduce")
    if args.out is not None:
        check_output_folder(args.out)
    reproduce(
        args.run,
        overrides=overrides,
        start_offset=args.start_offset,
        out_dir=args.out,
        replay=not args.no_replay,
        heldout=args.heldout,
        progress=_print,
    )


def teleop_command(args):
    """``hemg-drake teleop``: takes at the browser page (or one replayed from its inputs)."""
    from hemg_drake.scenario import load_scenario
    from hemg_drake.teleop_session import TakeNotKept, existing_takes, teleop

    scenario = load_scenario(_scenario_path(args.scenario), overrides=args.set)
    check_output_folder(args.out)
    existing_takes(scenario, args.out)  # refuse a mismatched folder before opening a port
    visualization = page = None
    if args.replay_inputs is not None:
        if not Path(args.replay_inputs).is_file():
            raise ValueError(f"{args.replay_inputs}: no such inputs log")
        if args.takes != 1:
            raise ValueError("--takes needs a person at the page; --replay-inputs replays one")
    else:
        from hemg_drake.diagrams.visualization import Visualization
        from hemg_drake.teleop.browser_server import TeleopPageServer

        visualization = Visualization(0)
        page = TeleopPageServer(visualization.meshcat, task=scenario.task,
                                scale=scenario.workspace_mapping().scale, port=args.port,
                                assist=scenario.assist.mode)  # fmt: skip
        # The first line, always.
        _print(f"Teleop page: {page.url()} (open it in a browser; Meshcat on port "
               f"{visualization.port()})")  # fmt: skip
    kept = 0
    while kept < args.takes:
        try:
            written = teleop(
                scenario, args.out, visualization=visualization, duration=args.duration,
                replay_inputs=args.replay_inputs, replays=not args.no_replay, progress=_print,
                wait=args.replay_inputs is None and not args.no_wait, page=page,
            )  # fmt: skip
        except TakeNotKept as not_kept:
            said = {"discarded": "discarded", "empty": "nothing moved in it: discarded",
                    "page closed": "the page was closed: not saved"}  # fmt: skip
            _print(f"take not kept ({said[not_kept.reason]}); nothing written")
            if not_kept.reason == "page closed":
                break
            continue
        kept += 1
        _print("wrote " + ", ".join(str(path) for path in written))
    if args.replay_inputs is None:
        _print(f"{kept} take{'s' if kept != 1 else ''} kept in {args.out}")


def takes_command(args):
    """``hemg-drake takes``: list a run folder's takes, or remove one."""
    from hemg_drake.teleop_takes import list_takes, remove_take

    if args.remove is not None:
        for path in remove_take(args.run, args.remove, progress=_print):
            _print(f"wrote {path}")
        return
    for c, operator, seconds, samples, own, score in list_takes(args.run):
        files = ", ".join(own) if own else "-"
        _print(f"{c:3d}  {operator:<10s} {seconds:7.2f} s  {samples:6d} samples  {files}"
               + ("" if score is None else f"  ({score})"))  # fmt: skip


def emg_figure_command(args):
    """``hemg-drake emg-figure``: Fig. 6 of a recording, or of a synthetic one."""
    import numpy as np

    from hemg_drake.emg.sources import MYO_RATE, load_emg_recording, synthesize_emg
    from hemg_drake.viz.figures import plot_emg_envelopes, save_figure

    check_output_file(args.output)
    if args.input:
        samples = load_emg_recording(args.input)
        count = len(samples)
        source = f"{args.input} ({count} sample{'s' if count != 1 else ''})"
    else:
        if args.duration * MYO_RATE < 1:
            raise ValueError(f"--duration must be at least one sample (5 ms), got {args.duration}")
        # Two contractions rising from rest and relaxing, 2.5 s each, then rest.
        time = np.arange(int(args.duration * MYO_RATE)) / MYO_RATE
        activation = 0.05 + 0.9 * np.clip(np.sin(np.pi * time / 2.5), 0.0, None) ** 2
        samples = synthesize_emg(activation, args.seed)
        source = f"a synthetic recording of {len(samples)} samples"
    too_long = [w for w in args.windows if w > len(samples)]
    if too_long:
        raise ValueError(
            f"--windows {too_long} longer than {source}: a window must be at most the "
            f"recording's length"
        )
    figure = plot_emg_envelopes(samples, args.windows, per_channel=args.per_channel)
    save_figure(figure, args.output)
    _print(f"wrote {args.output}")


def sweep_command(args):
    """``hemg-drake sweep``: run a sweep file's trials; the summary on stdout, each failed
    trial on stderr, and exit status 1 when any trial failed.

    Interrupted (Ctrl-C, SIGTERM), the workers stop with it and the one line says where the
    finished trials are kept.
    """
    from hemg_drake.sweep import load_sweep, run_sweep, summary
    from hemg_drake.sweep.folder import finished_trials

    if args.address and args.backend != "ray":
        raise ValueError("--address joins a Ray cluster: it needs --backend ray")
    check_output_folder(args.out)
    try:
        records = run_sweep(
            args.sweep, args.out, backend=args.backend, workers=args.workers,
            address=args.address, resume=args.resume,
        )  # fmt: skip
    except BaseException as error:
        # KeyboardInterrupt, or the entry point's Terminated: main prints its args.
        if not isinstance(error, Exception):
            kept = len(finished_trials(args.out))
            if kept:
                error.args = (f"no partial trial kept; {kept} finished trial(s) in "
                              f"{Path(args.out) / 'trials'}: --resume goes on",)  # fmt: skip
        raise
    spec = load_sweep(args.sweep)[0]
    for line in summary(records, spec):
        _print(line)
    failed = [r for r in records if r["status"] == "failed"]
    for record in failed:
        print(f"hemg-drake sweep: trial {record['id']} failed: {record['error']}",
              file=sys.stderr)  # fmt: skip
    _print(f"wrote {Path(args.out) / 'results.csv'} ({len(records)} trials, {len(failed)} failed)")
    return 1 if failed else 0


def export_command(args):
    """``hemg-drake export``: write a run's demonstrations as robomimic HDF5 (a file) or a
    LeRobot v3.0 dataset (a folder, with each frame's HSMM state when the run folder holds a
    model learnt from its dataset)."""
    from hemg_drake.learning.demos import load_dataset
    from hemg_drake.run_folder import RunFolder

    run = Path(args.run)
    folder = None if run.is_file() else RunFolder(run)
    dataset = run if folder is None else folder.dataset
    if args.format == "lerobot":
        from hemg_drake.learning.lerobot import check_output, export_lerobot

        check_output_folder(args.output)
        check_output(args.output)
        demos, metadata = load_dataset(dataset)
        states = _hsmm_states(folder, demos, metadata)
        total = export_lerobot(
            args.output, demos, metadata, fps=_fps(metadata), hsmm_states=states
        )
        extra = ", HSMM states" if states is not None else ""
    else:
        from hemg_drake.learning.export import export_robomimic

        check_output_file(args.output)
        demos, metadata = load_dataset(dataset)
        total = export_robomimic(args.output, demos, metadata)
        extra = ""
    count = len(demos)
    _print(
        f"wrote {args.output} ({count} demonstration{'s' if count != 1 else ''}, {total} "
        f"samples{extra}, {args.format})"
    )


def _fps(metadata):
    """1 / the dataset scenario's log period, or None (found from the sample times)."""
    from hemg_drake.scenario import parse_scenario

    if "scenario" not in metadata:
        return None
    return 1.0 / parse_scenario(metadata["scenario"], source="dataset metadata").log_period


def _hsmm_states(folder, demos, metadata):
    """Each demonstration's HSMM states (segmental Viterbi), if the run folder holds a model
    that its manifest records as learnt from this dataset; None otherwise."""
    from hemg_drake.pipeline import demonstration_frames, learning_data
    from hemg_drake.scenario import parse_scenario

    if folder is None or not folder.model.is_file() or "scenario" not in metadata:
        return None
    hint = f"hemg-drake learn {folder.path}"
    try:
        folder.check("learn", folder.model, run_hint=hint)
        folder.check_made_from("learn", folder.dataset, run_hint=hint)
    except ValueError:
        return None  # a model of another dataset: its states would mean nothing here
    from hemg_drake.learning.tphsmm import load_model
    from hemg_drake.placements import last_frames

    scenario = parse_scenario(metadata["scenario"], source=f"{folder.dataset} metadata")
    model = load_model(folder.model)
    data = learning_data(demos, scenario)
    frames = demonstration_frames(demos, scenario)
    states = []
    for c, demo in enumerate(data):
        at = model.at(*last_frames(frames[c], model.n_frames_)) if hasattr(model, "at") else model
        try:
            states.append(at.decode(demo)[1])
        except ValueError as error:
            raise ValueError(f"{folder.model}: demonstration {c + 1}: {error}") from None
    return states


def import_robomimic_command(args):
    """``hemg-drake import``: read robomimic HDF5 into a run folder's dataset."""
    from hemg_drake.learning.demos import save_dataset
    from hemg_drake.learning.export import load_robomimic
    from hemg_drake.run_folder import RunFolder

    demos, metadata = load_robomimic(args.input)  # read and checked before the folder
    check_output_folder(args.out)
    metadata["imported_from"] = str(args.input)
    with RunFolder.output(args.out).transaction("demonstrate", progress=_print) as folder:
        save_dataset(folder.dataset, demos, metadata)
        folder.finish("demonstrate", [folder.dataset], command="import")
    _print(f"wrote {folder.shown(folder.dataset)} ({len(demos)} demonstrations from {args.input})")


def repair_command(args):
    """``hemg-drake repair``: rebuild a run folder's manifest from the files there."""
    from hemg_drake.learning.demos import load_dataset
    from hemg_drake.run_folder import repair

    recorded = repair(args.run, check_dataset=load_dataset)
    for stage, names in recorded.items():
        _print(f"{stage}: {len(names)} file(s) recorded: {', '.join(names)}")
    _print(f"wrote {Path(args.run) / 'manifest.json'} (no other file was changed)")


def stability_command(args):
    """``hemg-drake stability``: the hold loop's spectral radius against delay (a table), the
    first unstable delay per gain, and optionally the figure."""
    from hemg_drake.scenario import load_scenario

    scenario = load_scenario(_scenario_path(args.scenario), overrides=args.set)
    if args.output:
        check_output_file(args.output)
    period_ms = 1e3 * scenario.master.period
    for delay in args.delays:
        if delay > MAX_STABILITY_DELAY_MS:
            raise ValueError(
                f"--delays {delay:g}: at most {MAX_STABILITY_DELAY_MS:g} ms (the linearised "
                "loop grows by 10 states per ms: 4040 states take 1 GB and 48 s at 400 ms)"
            )
        if delay < 0 or abs(round(delay / period_ms) * period_ms - delay) > 1e-9:
            raise ValueError(
                f"--delays {delay:g}: a delay must be a whole number of the master's "
                f"{period_ms:g} ms samples, >= 0"
            )
    from hemg_drake.analysis.stability import loop_stability, onset_delay

    gains = args.gains or [scenario.emg.k_min, scenario.emg.k_max]
    curves = {}
    for gain in gains:
        label = f"{scenario.feedback.mode}, K = {gain:g}"
        curves[label] = loop_stability(scenario, args.delays, gain=gain)
    _print("delay (ms)  " + "  ".join(f"{label:>28}" for label in curves))
    for row, delay in enumerate(args.delays):
        cells = []
        for results in curves.values():
            r = results[row]
            cells.append(f"{r.spectral_radius:.6f} ({r.frequency_hz:5.2f} Hz)".rjust(28))
        _print(f"{delay:10g}  " + "  ".join(cells))
    for label, results in curves.items():
        onset = onset_delay(results)
        verdict = "stable at every delay" if onset is None else f"unstable from {onset:g} ms"
        _print(f"{label}: {verdict} (spectral radius of the linearised loop about a hold)")
    if args.output:
        from hemg_drake.viz.figures import plot_loop_stability, save_figure

        save_figure(plot_loop_stability(curves, title=f"{scenario.task}: loop about a hold"), args.output)
        _print(f"wrote {args.output}")
