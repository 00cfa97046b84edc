"""The paper's loop as three steps on a run folder, and the full demo: what the CLI calls.

A run folder ``runs/NAME/`` holds one task's files::

    dataset.npz              C demonstrations (hemg-drake demonstrate)
    model.npz                the HSMM over [x, xdot, k]            (learn)
    state_activations.png    Fig. 8 (c)                            (learn)
    reproduction.html/.npz   replay and log of the reproduction    (reproduce)
    metrics.json             Table II, success, forces, stiffness  (reproduce)
    fig8_reproduction.png    cotter pin: Fig. 8 (d)-(f)            (reproduce)
    fig10_reproduction.png, fig11_strokes.png   drawing            (reproduce)

:func:`learn` and :func:`reproduce` check everything they read before writing anything, and
every file is written atomically, so a failed step leaves the folder as it was.
:func:`run_demo` runs demonstrate, learn and reproduce for both tasks (``make demo``).

Learning settings (measured on the two tasks' datasets, ``docs/reproduction.md``), per
task in ``LEARNING``: the positions learnt (the measured tool point, or the slave's
reference for the drawing, :func:`learning_data`), a left-to-right initialisation (equal
times for the pin, straight pieces of the path for the drawing; k-means shares states
between the drawing's look-alike strokes) and a covariance floor ``reg_covar`` (relative to
each dimension's variance), which keeps the integrated GMR velocity field (eqs. 16-18) from
amplifying deviations. The reproduction weighs the states by the HSMM's timing alone
(``"temporal"``) and adds the cross-track attractor of
:mod:`hemg_drake.learning.reproduce` (``RESTORING_GAIN``), so that a reproduction started
away from the demonstrations returns to their path.
"""

import json
import time
from pathlib import Path

import numpy as np

from hemg_drake.fileio import write_text_atomic

TASKS = ("cotter_pin", "drawing")
SCENARIOS_DIR = Path(__file__).resolve().parents[1] / "scenarios"
DATASET, MODEL = "dataset.npz", "model.npz"
# What the HSMM learns its positions from, and how its states start, per task (measured,
# docs/reproduction.md). Drawing: the slave's reference (a pen on the sheet cannot show the
# press in its measured position) and states that start where its path turns (the
# zig-zag's corners get their own states). Cotter pin: the measured tool point (the
# reference runs ahead of the pin while the detent holds it, and learnt from it the
# reproduction tracked the demonstrations less well) and states at equal times (its path
# is one straight line whose phases differ in speed and force, not direction).
# The drawing's covariance floor is lower than the pin's: its polyline states are narrow
# straight pieces, and 0.2 drew its strokes in shape best (0.1: 4.3 mm zig-zag, 0.5: 5.3 mm).
LEARNING = {
    "cotter_pin": {"positions": "tool", "init": "time", "reg_covar": 0.5},
    "drawing": {"positions": "reference", "init": "polyline", "reg_covar": 0.2},
}
DEFAULT_WEIGHTING = "temporal"
# kappa of the reproducer's cross-track attractor (1/s): a start offset decays towards the
# demonstrated path with the time constant 1 / kappa (docs/reproduction.md).
RESTORING_GAIN = 2.0
# Start offsets of the demo's second reproduction (m), 3 cm from the demonstrations' start,
# across the task's path: x*_0 is there and the arm starts at rest where the PD holds it.
# Cotter pin: sideways of the pull axis. The grasp holds the ring from t = 0 (the scene's
# model), as if the hand were pushed aside after grasping: the stiff grasp keeps the tool
# a few mm from the ring against the soft arm (settled_arm_positions), and the reproduction
# brings x* back onto the pull axis before it pulls. Drawing: sideways, above the sheet.
START_OFFSETS = {"cotter_pin": (0.03, 0.0, 0.0), "drawing": (0.0, 0.03, 0.0)}
# Drawing: shortest pen contact (log samples, 0.01 s each) that counts as a stroke.
MIN_STROKE_SAMPLES = 10


def _run_dir(run_dir):
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise FileNotFoundError(f"run folder not found: {run_dir}")
    return run_dir


def _load_demonstrations(run_dir):
    """(demos, scenario) of a run folder's dataset."""
    from hemg_drake.learning.demos import load_dataset
    from hemg_drake.scenario import parse_scenario

    path = run_dir / DATASET
    demos, metadata = load_dataset(path)
    if "scenario" not in metadata:
        raise ValueError(
            f"{path}: the metadata holds no scenario (record it with hemg-drake demonstrate)"
        )
    return demos, parse_scenario(metadata["scenario"], source=f"{path} metadata")


def check_enough_data(observations, n_states):
    """Raise ValueError unless C >= 2 demonstrations hold enough samples for N states.

    One demonstration shows no variability to learn (its covariances are degenerate), and
    N full-covariance Gaussians over D dimensions need at least N (D + 1) samples.
    """
    count = len(observations)
    samples = sum(len(x) for x in observations)
    n_dims = observations[0].shape[1]
    if count < 2 or samples < n_states * (n_dims + 1):
        raise ValueError(
            f"too few demonstrations for N = {n_states} states: {count} demonstration(s), "
            f"{samples} samples; need at least 2 and {n_states * (n_dims + 1)} samples"
        )


def learning_data(demos, scenario):
    """The observations the HSMM learns, [x, xdot, k] per demonstration, shape (T_c, 7).

    With ``LEARNING[task]["positions"]`` = "tool": the measured tool point p_WE, v_WE.
    With "reference": the slave's reference during the demonstration, the master's
    position mapped by the scenario's workspace map (what CLIK tracked), and its rate of
    change (central differences over the log). The reproduction's x* is a reference that
    the slave tracks with the learnt stiffness k; it is the pair (reference, stiffness) that
    made the demonstrated contact force. Learnt from the tool point, a pen on the sheet
    teaches a reference on the sheet's surface and the reproduction barely presses
    (measured: strokes broke off). k is the gain in both cases.
    """
    from hemg_drake.diagrams.demonstration import workspace_mapping
    from hemg_drake.learning.demos import observations

    if LEARNING[scenario.task]["positions"] == "tool":
        return observations(demos)
    mapping = workspace_mapping(scenario)
    data = []
    for demo in demos:
        p_WE_desired = mapping.master_to_slave(demo.p_MS)
        v_WE_desired = np.gradient(p_WE_desired, demo.time, axis=0)
        data.append(np.column_stack([p_WE_desired, v_WE_desired, demo.gain]))
    return data


def fit_model(data, scenario, *, n_iter=100):
    """The HSMM of the pipeline's settings (``LEARNING``) fitted to ``data``."""
    from hemg_drake.learning.hsmm import HSMM

    check_enough_data(data, scenario.num_states)
    settings = LEARNING[scenario.task]
    return HSMM(
        scenario.num_states,
        init=settings["init"],
        reg_covar=settings["reg_covar"],
        n_iter=n_iter,
        seed=scenario.seed,
    ).fit(data)


def learn(run_dir, *, n_iter=100, progress=print):
    """Fit the HSMM of a run folder's dataset; write ``model.npz`` and Fig. 8 (c).

    N is the scenario's ``num_states`` (stored with the dataset); the observations are
    :func:`learning_data`, [x_d, xdot_d, gain] (D = 7).

    Parameters
    ----------
    run_dir : path-like, holding ``dataset.npz``.
    n_iter : int, largest number of EM iterations.
    progress : callable taking one line of text.

    Returns
    -------
    HSMM, the fitted model.
    """
    from hemg_drake.viz.figures import plot_state_activations, save_figure

    run_dir = _run_dir(run_dir)
    demos, scenario = _load_demonstrations(run_dir)
    data = learning_data(demos, scenario)
    start = time.perf_counter()
    model = fit_model(data, scenario, n_iter=n_iter)
    progress(
        f"learn: HSMM N = {model.n_states} on {len(data)} demonstrations, {model.n_iter_} EM "
        f"iterations in {time.perf_counter() - start:.1f} s"
    )
    figure = plot_state_activations(
        demos[0].time,
        model.forward_variable(data[0]),
        title="HSMM state activations on demonstration 1 (Fig. 8 (c))",
    )
    model.save(run_dir / MODEL)
    save_figure(figure, run_dir / "state_activations.png")
    progress(f"wrote {run_dir / MODEL}, {run_dir / 'state_activations.png'}")
    return model


def reproduce(
    run_dir,
    *,
    start_offset=(0.0, 0.0, 0.0),
    weighting=DEFAULT_WEIGHTING,
    restoring_gain=RESTORING_GAIN,
    out_dir=None,
    replay=True,
    progress=print,
):
    """Simulate the learnt task from a start; write the replay, the log, figures and metrics.

    Parameters
    ----------
    run_dir : path-like, holding ``dataset.npz`` and ``model.npz``.
    start_offset : 3 floats, m
        Added to the demonstrations' mean start position.
    weighting : {"temporal", "spatial", "forward"}
        State weighting of the reproducer.
    restoring_gain : float
        kappa of the reproducer's cross-track attractor (1/s).
    out_dir : path-like, optional
        Where to write (created); default ``run_dir``.
    replay : bool
        Write ``reproduction.html``.
    progress : callable taking one line of text.

    Returns
    -------
    dict, the metrics written to ``metrics.json``.
    """
    from hemg_drake.diagrams.reproduction import check_model, run_reproduction
    from hemg_drake.learning.hsmm import HSMM

    run_dir = _run_dir(run_dir)
    demos, scenario = _load_demonstrations(run_dir)
    model = HSMM.load(run_dir / MODEL)
    try:
        check_model(model)
    except ValueError as error:
        raise ValueError(f"{run_dir / MODEL}: {error}") from None
    offset = np.asarray(start_offset, dtype=float)
    if offset.shape != (3,) or not np.all(np.isfinite(offset)):
        raise ValueError(f"start offset must be 3 finite numbers (m), got {start_offset!r}")
    start = np.mean([demo.p_WE[0] for demo in demos], axis=0) + offset
    duration = float(np.mean([demo.time[-1] for demo in demos]))
    out_dir = run_dir if out_dir is None else Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    began = time.perf_counter()
    result = run_reproduction(
        scenario,
        model,
        duration=duration,
        start=start,
        weighting=weighting,
        restoring_gain=restoring_gain,
        replay_path=out_dir / "reproduction.html" if replay else None,
    )
    progress(
        f"reproduce: {scenario.task}, {weighting} weighting, start offset "
        f"{np.round(offset, 4).tolist()} m: {duration:g} s simulated in "
        f"{time.perf_counter() - began:.1f} s"
    )
    metrics = task_metrics(scenario.task, demos, result)
    metrics.update(
        weighting=weighting,
        restoring_gain=restoring_gain,
        start=start.tolist(),
        start_offset=offset.tolist(),
    )
    result.log.save(out_dir / "reproduction.npz")
    _write_figures(scenario.task, demos, result.log, out_dir)
    write_text_atomic(out_dir / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    progress(format_metrics({scenario.task: metrics}))
    written = "(.html, .npz)" if replay else "(.npz)"
    progress(f"wrote {out_dir}/: reproduction {written}, figures, metrics.json")
    return metrics


def task_metrics(task, demos, result):
    """Table II, task success, tracking force and stiffness of one reproduction.

    Parameters
    ----------
    task : {"cotter_pin", "drawing"}
    demos : list of Demonstration
    result : ReproductionResult

    Returns
    -------
    dict (JSON-ready): ``alignment`` (the method), ``position_rmse_m``,
    ``velocity_rmse_m_per_s``, ``time_normalised`` (the same RMSEs, other alignment),
    ``stiffness_correlation``, ``tracking_force_peak_n``, ``tracking_force_mean_n``,
    ``success``, and the task's own entries.
    """
    from hemg_drake.learning.demos import observations
    from hemg_drake.tasks import metrics

    log = result.log
    data = observations(demos)
    reproduced = log.observations()
    mean = metrics.mean_demonstration(data)
    aligned = metrics.aligned_rmse(reproduced, mean)
    plain = metrics.time_normalised_rmse(reproduced, data)
    force = metrics.force_statistics(log.F_tr)
    record = {
        "alignment": metrics.ALIGNMENT,
        "position_rmse_m": aligned["position_rmse"],
        "velocity_rmse_m_per_s": aligned["velocity_rmse"],
        "time_normalised": {
            "position_rmse_m": plain["position_rmse"],
            "velocity_rmse_m_per_s": plain["velocity_rmse"],
        },
        "stiffness_correlation": metrics.stiffness_correlation(
            reproduced[:, 6], mean[:, 6], aligned["path"]
        ),
        "tracking_force_peak_n": force["peak"],
        "tracking_force_mean_n": force["mean"],
    }
    if task == "cotter_pin":
        record.update(
            success=bool(result.pin_out),
            pin_displacement_m=result.pin_displacement,
        )
    else:
        record.update(_drawing_metrics(demos, log))
    return record


def _strokes(time, p_WE, f_WE):
    from hemg_drake.viz.ink import in_contact, ink_strokes

    return ink_strokes(time, p_WE, in_contact(f_WE), min_points=MIN_STROKE_SAMPLES)


def _drawing_metrics(demos, log):
    """Strokes, their shape and placement errors (seen from above), stiffness on and off paper."""
    from hemg_drake.tasks.metrics import stroke_errors
    from hemg_drake.viz.ink import in_contact

    strokes = _strokes(log.time, log.p_WE, log.f_WE)
    demo_strokes = [_strokes(d.time, d.p_WE, d.f_WE) for d in demos]
    shape, placement = [], []
    for k, stroke in enumerate(strokes):
        same = [s[k][:, :2] for s in demo_strokes if len(s) > k]
        errors = stroke_errors(stroke[:, :2], same) if same else None
        shape.append(errors and errors["shape"])
        placement.append(errors and errors["placement"])
    touching = in_contact(log.f_WE)
    on_paper = float(log.k_star[touching].mean()) if touching.any() else None
    in_air = float(log.k_star[~touching].mean()) if (~touching).any() else None
    return {
        "strokes": len(strokes),
        "demonstrated_strokes": [len(s) for s in demo_strokes],
        "stroke_shape_error_m": shape,
        "stroke_placement_error_m": placement,
        "success": len(strokes) == 3,
        "stiffness_on_paper": on_paper,
        "stiffness_in_air": in_air,
    }


def _write_figures(task, demos, log, out_dir):
    from hemg_drake.viz import figures

    if task == "cotter_pin":
        figure = figures.plot_pin_reproduction(demos, log)
        figures.save_figure(figure, out_dir / "fig8_reproduction.png")
    else:
        strokes = _strokes(log.time, log.p_WE, log.f_WE)
        demonstrated = [s for d in demos for s in _strokes(d.time, d.p_WE, d.f_WE)]
        figure = figures.plot_drawing_reproduction(demos, log)
        figures.save_figure(figure, out_dir / "fig10_reproduction.png")
        figure = figures.plot_strokes(strokes, demonstrated=demonstrated)
        figures.save_figure(figure, out_dir / "fig11_strokes.png")


def format_metrics(results):
    """A plain-text table of metrics per run (task name -> metrics dict)."""
    rows = [("run", "pos RMSE (mm)", "vel RMSE (m/s)", "success", "F_tr peak/mean (N)", "k corr")]
    for name, m in results.items():
        correlation = m["stiffness_correlation"]
        rows.append((
            name,
            f"{1e3 * m['position_rmse_m']:.2f}",
            f"{m['velocity_rmse_m_per_s']:.4f}",
            str(m["success"]),
            f"{m['tracking_force_peak_n']:.2f} / {m['tracking_force_mean_n']:.2f}",
            "-" if correlation is None else f"{correlation:.2f}",
        ))  # fmt: skip
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    lines.append("RMSE alignment: DTW against the mean demonstration (docs/reproduction.md)")
    return "\n".join(lines)


def run_demo(
    out_dir="runs", *, tasks=TASKS, changes=None, n_iter=100, replays=True, progress=print
):
    """The full demo: for each task, demonstrate, learn, reproduce (twice), draw and measure.

    Per task, ``out_dir/TASK/`` gets the dataset, demonstration replays and Fig. 8 (a)-(b) or
    Fig. 10 (demonstrations), Fig. 6 (the sEMG of demonstration 1), the model and Fig. 8 (c),
    the reproduction (replay, log, figures, metrics), a second reproduction from
    ``START_OFFSETS`` in ``start_offset/``, and the diagrams as SVG. ``out_dir/metrics.json``
    gathers the metrics; the table is printed.

    Parameters
    ----------
    out_dir : path-like
    tasks : sequence of task names
    changes : dict, optional
        Scenario fields to change for every task (e.g. ``{"num_demonstrations": 2}``), for
        small-scale runs.
    n_iter : int, EM iterations at most.
    replays : bool, write the HTML replays.
    progress : callable taking one line of text.

    Returns
    -------
    dict, run name -> metrics.
    """
    from hemg_drake.diagrams.demonstration import record_demonstrations
    from hemg_drake.scenario import load_scenario

    out_dir = Path(out_dir)
    unknown = [task for task in tasks if task not in TASKS]
    if unknown or not tasks:
        raise ValueError(f"tasks must be among {TASKS}, got {list(tasks)}")
    scenarios = {}
    for task in tasks:
        scenario = load_scenario(SCENARIOS_DIR / f"{task}.yaml")
        scenarios[task] = scenario.replaced(source="demo changes", **(changes or {}))
    results, began = {}, time.perf_counter()
    for task, scenario in scenarios.items():
        run_dir = out_dir / task
        progress(
            f"== {task}: {scenario.num_demonstrations} demonstrations of {scenario.duration:g} s, "
            f"N = {scenario.num_states} states -> {run_dir}/"
        )
        run_dir.mkdir(parents=True, exist_ok=True)
        for path in record_demonstrations(scenario, run_dir, replays=replays, progress=progress):
            progress(f"wrote {path}")
        _write_emg_figure(run_dir)
        model = learn(run_dir, n_iter=n_iter, progress=progress)
        results[task] = reproduce(run_dir, replay=replays, progress=progress)
        results[f"{task} (start 3 cm away)"] = reproduce(
            run_dir,
            start_offset=START_OFFSETS[task],
            out_dir=run_dir / "start_offset",
            replay=False,
            progress=progress,
        )
        _write_diagrams(scenario, model, run_dir)
        progress(f"== {task} done after {time.perf_counter() - began:.0f} s")
    write_text_atomic(out_dir / "metrics.json", json.dumps(results, indent=2) + "\n")
    progress(format_metrics(results))
    progress(f"wrote {out_dir / 'metrics.json'}; total {time.perf_counter() - began:.0f} s")
    return results


def _write_emg_figure(run_dir):
    """Fig. 6 from demonstration 1: its sEMG re-synthesised from the logged activation.

    The synthetic armband is deterministic in (activation, seed), so this is the signal
    the demonstration's gain chain read, up to the activation's hold between log samples.
    """
    from hemg_drake.emg.sources import MYO_RATE, synthesize_emg
    from hemg_drake.learning.demos import load_dataset
    from hemg_drake.viz.figures import plot_emg_envelopes, save_figure

    demo = load_dataset(run_dir / DATASET)[0][0]
    per_log_sample = max(1, int(round(MYO_RATE * np.mean(np.diff(demo.time)))))
    samples = synthesize_emg(np.repeat(demo.activation, per_log_sample), demo.seed)
    save_figure(plot_emg_envelopes(samples), run_dir / "fig6_emg.png")


def _write_diagrams(scenario, model, run_dir):
    """The demonstration and reproduction diagrams as SVG (Graphviz, every port)."""
    from hemg_drake.diagrams.demonstration import build_demonstration_diagram
    from hemg_drake.diagrams.reproduction import build_reproduction_diagram
    from hemg_drake.viz.diagram_svg import diagram_svg

    demonstration = build_demonstration_diagram(scenario, seed=scenario.seed).diagram
    reproduction = build_reproduction_diagram(scenario, model).diagram
    write_text_atomic(run_dir / "demonstration_diagram.svg", diagram_svg(demonstration))
    write_text_atomic(run_dir / "reproduction_diagram.svg", diagram_svg(reproduction))
