"""The paper's loop as three stages on a run folder, and the full demo: what the CLI calls.

Each stage reads what it needs once, checks it before writing anything, and records what it
wrote in the folder's manifest (:class:`~hemg_drake.run_folder.RunFolder`)::

    demonstrate(scenario, "runs/pin")   # dataset.npz, replays, Fig. 8 (a)-(b) / 10, Fig. 6
    learn("runs/pin")                   # model.npz, Fig. 8 (c)
    reproduce("runs/pin")               # reproduction replay, log, figures, metrics.json

Every setting comes from the scenario (stored in the dataset): the learning settings in its
``learning`` section, the reproduction's in ``reproduction``; ``overrides`` (``--set``)
change any of them for one call. :func:`hemg_drake.demo.run_demo` runs the three stages for both
shipped scenarios (``make demo``).
"""

import functools
import json
import time
import warnings
from pathlib import Path

import numpy as np

from hemg_drake.fileio import save_npz_atomic, write_text_atomic
from hemg_drake.run_folder import DATASET, MODEL, RunFolder

TASKS = ("cotter_pin", "drawing")
# The sub-folder of a run that holds its fresh demonstrations (demonstrate_heldout).
HELDOUT = "heldout"
# The demonstrations' interaction signals (hand force, stylus velocity, the assist's): the studies'.
INTERACTION_FILE = "interaction.npz"


def _demonstrate_hint(folder):
    # Never advice that replaces what is there (a person's takes): a new run goes elsewhere.
    return "hemg-drake demonstrate SCENARIO --out NEW_FOLDER for a new run"


def demonstrate_seed(built, seed, *, replay_path=None, title=None, signals=None):
    """Run demonstration ``seed`` on a built diagram; with ``replay_path`` (the diagram built
    with a Visualization), recorded into an HTML replay titled ``title``. With a list
    ``signals``, the run's interaction signals are appended to it
    (:func:`~hemg_drake.diagrams.demonstration.interaction_signals`)."""
    from hemg_drake.diagrams.demonstration import run_demonstration_logged
    from hemg_drake.viz.recording import record_run

    def run(b):
        demo, logged = run_demonstration_logged(b, seed)
        if signals is not None:
            signals.append(logged)
        return demo

    if replay_path is None:
        return run(built)
    return record_run(built, run, replay_path, title=title)


def check_enough_data(observations, n_states):
    """Raise ValueError unless C >= 2 demonstrations hold enough samples for N states.

    One demonstration shows no variability to learn (its covariances are degenerate), and
    N full-covariance Gaussians over D dimensions need at least N (D + 1) samples.
    """
    count = len(observations)
    samples = sum(len(x) for x in observations)
    n_dims = observations[0].shape[1]
    needed = n_states * (n_dims + 1)
    if count < 2 or samples < needed:
        raise ValueError(
            f"too few demonstrations for N = {n_states} states: {count} demonstration"
            f"{'s' if count != 1 else ''} of {samples} samples in all; N = {n_states} needs at "
            f"least 2 demonstrations and {needed} samples"
        )


def learning_data(demos, scenario):
    """The observations the HSMM learns, [x, xdot, k] per demonstration, shape (T_c, 7).

    With ``learning.positions`` = "tool": the measured tool point p_WE, v_WE. With
    "reference": the reference the CLIK received during the demonstration (logged, so a
    transport delay is in it) and its rate of change (central differences over the log).
    The reproduction's x* is a reference that the slave tracks with the learnt stiffness
    k; it is the pair (reference, stiffness) that made the demonstrated contact force.
    Learnt from the tool point, a pen on the sheet teaches a reference on the sheet's
    surface and the reproduction barely presses (measured: strokes broke off). k is the
    logged gain in both cases, logged at the same instants as the reference.
    With ``learning.align`` "trim" each is cut to its active span, with "dtw" time-warped
    onto the take of median length (learning/align.py).
    """
    return _learning_data(demos, scenario)[0]


def _learning_data(demos, scenario):
    """(:func:`learning_data`, the (begin, end) span of each demonstration it kept)."""
    from hemg_drake.learning.align import aligned
    from hemg_drake.learning.demos import observations

    data = observations(demos) if scenario.learning.positions == "tool" else [
        np.column_stack([d.p_WE_desired, np.gradient(d.p_WE_desired, d.time, axis=0), d.gain])
        for d in demos
    ]  # fmt: skip
    return aligned(data, scenario.learning.align)


def fit_model(data, scenario, *, n_iter=None, frames=None):
    """The HSMM of the scenario's ``learning`` settings fitted to ``data``.

    With ``frames`` (the demonstrations' task frames, list of (A, b)) that differ between
    demonstrations, or ``learning.task_parameterised``: a
    :class:`~hemg_drake.learning.tphsmm.TaskParameterisedHSMM` in those frames.
    """
    from hemg_drake.learning.hsmm import HSMM
    from hemg_drake.learning.tphsmm import TaskParameterisedHSMM
    from hemg_drake.placements import FRAME_SETS, frames_vary, last_frames

    settings = scenario.learning
    check_enough_data(data, settings.num_states)
    parameters = dict(
        init=settings.init,
        reg_covar=settings.reg_covar,
        n_iter=settings.n_iter if n_iter is None else n_iter,
        random_state=scenario.seed,
    )
    if frames is not None and (settings.task_parameterised or frames_vary(frames)):
        used = [last_frames(pair, FRAME_SETS[settings.task_frames]) for pair in frames]
        return TaskParameterisedHSMM(settings.num_states, **parameters).fit(data, used)
    return HSMM(settings.num_states, **parameters).fit(data)


def demonstration_frames(demos, scenario):
    """Each demonstration's task frames (A, b): recorded, or (format 2 datasets, one
    placement) the dataset scenario's."""
    from hemg_drake.placements import task_frames

    return [demo.frames or task_frames(scenario) for demo in demos]


def load_demonstrations(path):
    """(demos, scenario) of a dataset file, the scenario read from its metadata."""
    from hemg_drake.learning.demos import load_dataset
    from hemg_drake.scenario import parse_scenario

    demos, metadata = load_dataset(path)
    if "scenario" not in metadata:
        raise ValueError(
            f"{path}: the metadata holds no scenario (record it with hemg-drake demonstrate)"
        )
    return demos, parse_scenario(metadata["scenario"], source=f"{path} metadata")


def demonstrate(scenario, run_dir, *, replays=True, progress=print):
    """Run the scenario's C demonstrations into a run folder.

    Writes ``dataset.npz`` (:func:`~hemg_drake.learning.demos.save_dataset`, with the
    scenario's YAML, task and log period in the metadata), ``replay_<c>.html`` for
    c = 1 .. C when ``replays``, ``demonstrations.png`` (Fig. 8 (a)-(b) or Fig. 10) and
    ``fig6_emg.png`` (Fig. 6 from demonstration 1's logged sEMG). The outputs of an older
    run in the folder, and everything made from them, are removed first.

    Returns
    -------
    list of Path, the files written (dataset first).
    """
    from hemg_drake.placements import demonstration_scenario

    # Every placement drawn and checked within reach before anything is written.
    placed = [demonstration_scenario(scenario, seed) for seed in scenario.seeds()]
    with RunFolder.output(run_dir).transaction("demonstrate", progress=progress) as folder:
        written = _demonstrate(scenario, folder, replays, progress, placed)
    return [folder.shown(path) for path in written]


def _demonstrate(scenario, folder, replays, progress, placed):
    import dataclasses as dc

    from hemg_drake.placements import describe_placement, has_placements, task_frames
    from hemg_drake.diagrams.demonstration import build_demonstration_diagram, operator_plan
    from hemg_drake.diagrams.visualization import Visualization
    from hemg_drake.learning.demos import save_dataset
    from hemg_drake.viz.run_figures import write_demonstration_figures

    demos, replay_files, signals = [], [], []
    visualization = Visualization() if replays else None  # one server for every replay
    # One diagram per placement (the seeds live in the Context): without placements, one.
    diagrams = {}
    for c, (seed, here) in enumerate(zip(scenario.seeds(), placed, strict=True), start=1):
        replay = folder / f"replay_{c}.html" if replays else None
        title = f"{scenario.task.replace('_', ' ')}: demonstration {c} (seed {seed})"
        start = time.perf_counter()
        key = here.to_yaml()
        if key not in diagrams:
            diagrams[key] = build_demonstration_diagram(here, visualization=visualization)
        demos.append(demonstrate_seed(
            diagrams[key], seed, replay_path=replay, title=title, signals=signals
        ))  # fmt: skip
        if has_placements(scenario):
            progress(f"demonstration {c}: {describe_placement(here)}")
        if replay is not None:
            replay_files.append(replay)
        plan_end = operator_plan(scenario, seed).end_time
        progress(
            f"demonstration {c}/{scenario.num_demonstrations} (seed {seed}): "
            f"{scenario.duration:g} s simulated in {time.perf_counter() - start:.1f} s"
            + (f", replay {folder.shown(replay)}" if replay else "")
            + (
                f"; cut short: the operator's plan ends at {plan_end:.2f} s"
                if plan_end > scenario.duration
                else ""
            )
        )
    frames = [task_frames(here) for here in placed]
    demos = [dc.replace(d, frame_A=A, frame_b=b) for d, (A, b) in zip(demos, frames, strict=True)]
    metadata = dict(scenario=scenario.to_yaml(), task=scenario.task, log_period=scenario.log_period)
    save_dataset(folder.dataset, demos, metadata)
    written = [folder.dataset]
    if len(signals) == len(demos):  # the operator's effort, the assist's signals: the studies'
        interaction = folder / INTERACTION_FILE
        save_npz_atomic(interaction, **{
            f"demo{c}.{name}": value for c, logged in enumerate(signals)
            for name, value in logged.items()
        })  # fmt: skip
        written.append(interaction)
    figures = write_demonstration_figures(demos, scenario, folder.path)
    written += [*replay_files, *figures]
    folder.finish("demonstrate", written)
    return written


def demonstrate_heldout(scenario, run_dir, *, progress=print):
    """Record the scenario's fresh demonstrations (``reproduction.num_heldout`` of them from
    seed ``reproduction.heldout_seed``, at the scenario's placement, no replays) into
    ``run_dir/heldout/``, a run folder of its own; :func:`reproduce` scores against them.

    Returns
    -------
    Path, the folder.
    """
    fresh = scenario.reproduction
    if fresh.num_heldout < 1:
        raise ValueError("key 'reproduction.num_heldout' is 0: no fresh demonstrations to record")
    folder = Path(run_dir) / HELDOUT
    overrides = [f"seed={fresh.heldout_seed}", f"num_demonstrations={fresh.num_heldout}",
                 "reproduction.num_heldout=0"]  # fmt: skip
    demonstrate(scenario.replaced(overrides), folder, replays=False, progress=progress)
    return folder


def learn(run_dir, *, overrides=(), n_iter=None, diagrams=False, progress=print):
    """Fit the HSMM of a run folder's dataset; write ``model.npz`` and Fig. 8 (c).

    N and every other setting are the scenario's ``learning`` section (stored with the
    dataset); the observations are :func:`learning_data` (D = 7).

    Parameters
    ----------
    run_dir : path-like, holding ``dataset.npz``.
    overrides : sequence of str
        ``key=value`` changes to the dataset's scenario (e.g. ``"learning.num_states=6"``).
    n_iter : int, optional
        Largest number of EM iterations; default ``learning.n_iter``.
    diagrams : bool
        Also draw the demonstration and reproduction diagrams
        (:func:`~hemg_drake.viz.run_figures.write_run_diagrams`).
    progress : callable taking one line of text.

    Returns
    -------
    HSMM, the fitted model.
    """
    from hemg_drake.folder_lock import folder_lock

    folder = RunFolder(run_dir)
    with folder_lock(folder.path):
        return _learn(folder, overrides, n_iter, diagrams, progress)


def _learn(folder, overrides, n_iter, diagrams, progress):
    from hemg_drake.placements import last_frames, scene_placements
    from hemg_drake.viz.run_figures import write_run_diagrams, write_state_activations_figure

    folder.check("demonstrate", folder.dataset, run_hint=_demonstrate_hint(folder))
    demos, scenario = load_demonstrations(folder.dataset)
    scenario = scenario.replaced(overrides)
    data, spans = _learning_data(demos, scenario)
    frames = demonstration_frames(demos, scenario)
    start = time.perf_counter()
    model = fit_model(data, scenario, n_iter=n_iter, frames=frames)
    model.learnt_at_ = scene_placements(frames)  # stored in model.npz
    iterations = f"{model.n_iter_} EM iteration{'s' if model.n_iter_ != 1 else ''}"
    frame_names = scenario.learning.task_frames.replace("_", " ")
    kind = "HSMM" if not hasattr(model, "at") else f"TP-HSMM (task frames: {frame_names})"
    progress(
        f"learn: {kind} N = {model.n_states} on {len(data)} demonstrations, {iterations} in "
        f"{time.perf_counter() - start:.1f} s"
        + ("" if model.converged_ else " (stopped before converging: raise --iterations)")
    )
    first = model
    if hasattr(model, "at"):  # a TP-HSMM: its HSMM where demonstration 1 was
        first = model.at(*last_frames(frames[0], model.n_frames_))
    h = first.forward_variable(data[0])
    with folder.transaction("learn", progress=progress) as new:
        model.save(new.model)
        written = [new.model]
        # Demonstration 1's times as learnt (cut by "trim", on the reference's samples by "dtw").
        time_0 = demos[0].time[spans[0][0]] + scenario.log_period * np.arange(len(data[0]))
        written.append(write_state_activations_figure(time_0, h, scenario.task, new.path))
        if diagrams:
            written += write_run_diagrams(scenario, placed_model(model, scenario), new.path,
                                          progress=progress)  # fmt: skip
        new.finish("learn", written, inputs=[new.dataset])
    progress("wrote " + ", ".join(str(new.shown(path)) for path in written))
    return model


def placed_model(model, scenario):
    """The HSMM to reproduce with at the scenario's placement: a TP-HSMM's product in the
    scenario's task frames (``hemg_drake.placements.task_frames``), a plain HSMM itself."""
    from hemg_drake.placements import last_frames, task_frames

    if not hasattr(model, "at"):
        return model
    return model.at(*last_frames(task_frames(scenario), model.n_frames_))


def _checked_model(folder, scenario, frames):
    """The run folder's model at the scenario's placement, refused unless it was fitted on
    the folder's dataset; a warning if a world-frame model is moved from where it learnt."""
    from hemg_drake.diagrams.reproduction import check_model
    from hemg_drake.learning.tphsmm import load_model
    from hemg_drake.placements import check_learnt_placement

    hint = f"hemg-drake learn {folder.path}"
    folder.check("demonstrate", folder.dataset, run_hint=_demonstrate_hint(folder))
    folder.check("learn", folder.model, run_hint=hint)
    folder.check_made_from("learn", folder.dataset, run_hint=hint)
    learnt = load_model(folder.model)
    # Said once every check has passed (a refused run says one line: its error).
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_learnt_placement(learnt, scenario, frames, source=folder.model)
    model = placed_model(learnt, scenario)
    try:
        check_model(model)
    except ValueError as error:
        raise ValueError(f"{folder.model}: {error}") from None
    model_warnings = [str(w.message) for w in caught]
    return model, model_warnings


def reproduce(
    run_dir, *, overrides=(), start_offset=(0.0, 0.0, 0.0), out_dir=None, replay=True,
    heldout=None, progress=print,
):  # fmt: skip
    """Simulate the learnt task from a start; write the replay, the log, figures and metrics.

    Parameters
    ----------
    run_dir : path-like, holding ``dataset.npz`` and the ``model.npz`` fitted on it.
    overrides : sequence of str
        ``key=value`` changes to the dataset's scenario (e.g.
        ``"reproduction.weighting=forward"``).
    start_offset : 3 floats, m
        Added to the demonstrations' mean start position, in the scene frame.
    out_dir : path-like, optional
        Where to write (created); default ``run_dir``.
    replay : bool
        Write ``reproduction.html``.
    heldout : path-like, optional
        A run folder of fresh demonstrations of the same task (:func:`demonstrate_heldout`;
        seeds disjoint from the training ones): the metrics lead with the reproduction
        scored against them (``evaluation.task_metrics``), and name their seeds.
    progress : callable taking one line of text.

    Returns
    -------
    dict, the metrics written to ``metrics.json``.
    """
    from hemg_drake.folder_lock import folder_lock

    folder = RunFolder(run_dir)
    same = out_dir is None or Path(out_dir).resolve() == folder.path.resolve()
    out = folder if same else RunFolder.output(out_dir)
    # The run is read throughout: no other command may replace it meanwhile.
    with folder_lock(folder.path, shared=out is not folder):
        fresh = None if heldout is None else _fresh_demonstrations(folder, heldout)
        return _checked_reproduce(folder, out, overrides, start_offset, replay, progress, fresh)


def _fresh_demonstrations(folder, heldout):
    """(demos, scenario, dataset path) of the fresh demonstrations in run folder ``heldout``,
    refused unless of the same task as ``folder``'s and from seeds disjoint from its."""
    fresh = RunFolder(heldout)
    hint = f"hemg-drake demonstrate ... --out {heldout}"
    fresh.check("demonstrate", fresh.dataset, run_hint=hint)
    demos, scenario = load_demonstrations(fresh.dataset)
    _, recorded = load_demonstrations(folder.dataset)
    shared = sorted(set(scenario.seeds()) & set(recorded.seeds()))
    if scenario.task != recorded.task or shared:
        raise ValueError(
            f"{fresh.dataset}: fresh demonstrations must be of the same task ({recorded.task}) "
            f"from other seeds than {folder.dataset}'s; got {scenario.task}, seeds "
            f"{scenario.seeds()}" + (f" (shared: {shared})" if shared else "")
        )
    return demos, scenario, fresh.dataset


def _checked_reproduce(folder, out, overrides, start_offset, replay, progress, fresh=None):
    from hemg_drake.placements import moved_demonstration, scene_frame, task_frames

    demos, recorded = load_demonstrations(folder.dataset)
    scenario = recorded.replaced(overrides)
    model, notes = _checked_model(folder, scenario, demonstration_frames(demos, recorded))
    offset = np.asarray(start_offset, dtype=float)
    if offset.shape != (3,) or not np.all(np.isfinite(offset)):
        raise ValueError(f"start offset must be 3 finite numbers (m), got {start_offset!r}")
    # The demonstrations carried to the scene's placement (themselves where they were shown):
    # the start and what the metrics compare with.
    here = scene_frame(*task_frames(scenario))
    def placed(demos, recorded):
        return [
            moved_demonstration(demo, scene_frame(*frames), here)
            for demo, frames in zip(demos, demonstration_frames(demos, recorded), strict=True)
        ]

    demos = placed(demos, recorded)
    if fresh is not None:
        fresh = dict(demos=placed(*fresh[:2]), seeds=fresh[1].seeds(), dataset=fresh[2],
                     training_seeds=recorded.seeds())  # fmt: skip
    offset_W = scenario.X_WT().rotation().matrix() @ offset
    start = np.mean([demo.p_WE[0] for demo in demos], axis=0) + offset_W
    if out is not folder and (out.dataset.exists() or out.model.exists()):
        raise ValueError(
            f"--out {out.path} holds a run of its own ({DATASET} or {MODEL}); write the "
            f"reproduction into a new folder or the run folder itself"
        )
    with out.transaction("reproduce", progress=progress) as new:
        return _reproduce(scenario, model, demos, folder, new, start, offset, replay, progress,
                          fresh, notes)  # fmt: skip


def _reproduce(scenario, model, demos, folder, out, start, offset, replay, progress, fresh,
               notes=()):  # fmt: skip
    from hemg_drake.diagrams.reproduction import build_reproduction_diagram, run_reproduction
    from hemg_drake.diagrams.visualization import Visualization
    from hemg_drake.evaluation import format_metrics, task_metrics
    from hemg_drake.learning.demos import demonstrated_gain
    from hemg_drake.viz.recording import record_run
    from hemg_drake.viz.run_figures import write_reproduction_figures

    duration = float(np.mean([demo.time[-1] for demo in demos]))
    settings = scenario.reproduction
    began = time.perf_counter()
    title = f"{scenario.task.replace('_', ' ')}: reproduction from {out.final.name}"
    visualization = Visualization() if replay else None
    gain = demonstrated_gain(demos, duration) if settings.gain_source == "demonstrated" else None
    built = build_reproduction_diagram(scenario, model, start=start, visualization=visualization,
                                       demonstrated_gain=gain)  # fmt: skip
    for note in notes:  # the diagram is built: the scene is reachable, the run will go
        warnings.warn(note, stacklevel=2)
    replay_path = out / "reproduction.html" if replay else None
    run = functools.partial(run_reproduction, duration=duration)
    result = record_run(built, run, replay_path, title=title) if replay else run(built)
    progress(
        f"reproduce: {scenario.task}, {settings.tracker} tracker, {settings.weighting} "
        f"weighting, start offset "
        f"{np.round(offset, 4).tolist()} m: {duration:g} s simulated in "
        f"{time.perf_counter() - began:.1f} s"
    )
    metrics = task_metrics(scenario.task, demos, result, fresh and fresh["demos"])
    if fresh is not None:
        metrics["out_of_sample"].update(
            seeds=fresh["seeds"], training_seeds=fresh["training_seeds"]
        )
    metrics.update(
        tracker=settings.tracker,
        weighting=settings.weighting,
        gain_source=settings.gain_source,
        # The attractor is eqs. 15-18's; the LQR returns to the path by re-planning.
        restoring_gain=settings.restoring_gain if settings.tracker == "gmr" else None,
        start=start.tolist(),
        start_offset=offset.tolist(),
        scene_position=scenario.X_WT().translation().tolist(),
        scene_yaw_deg=scenario.scene.yaw_deg,
    )
    written = [out / "reproduction.npz", out / "metrics.json"]
    save_npz_atomic(written[0], **result.log.arrays())
    written += write_reproduction_figures(scenario.task, demos, result.log, out.path)
    write_text_atomic(written[1], json.dumps(metrics, indent=2) + "\n")
    if replay_path is not None:
        written.append(replay_path)
    inputs = [folder.model, folder.dataset] + ([fresh["dataset"]] if fresh else [])
    out.finish("reproduce", written, inputs=inputs)
    progress(format_metrics({scenario.task: metrics}))
    progress(f"wrote {out.final}/: " + ", ".join(p.name for p in written))
    return metrics
