"""A take at the teleop page, and the run folder it is recorded into.

:func:`run_take` runs the demonstration diagram with a
:class:`~hemg_drake.teleop.browser.BrowserMaster` for one take (live at real time with the
page of :class:`~hemg_drake.teleop.browser_page.TeleopPage`, or replayed from an inputs
log); :func:`teleop` appends takes to a run folder's dataset (``hemg-drake teleop``).
"""

import dataclasses as dc
import time
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator

from hemg_drake._validate import as_scalar
from hemg_drake.teleop.browser import BrowserMaster
from hemg_drake.teleop.browser_inputs import (
    END_KEY,
    InputsLog,
    LoggedInputs,
    MeshcatInputs,
    load_inputs,
    save_inputs,
)
from hemg_drake.teleop.browser_page import TeleopPage, operator_view
from hemg_drake.teleop_takes import template_score, template_strokes

# The page is refreshed, and the simulator advanced, in steps of this (s): 32 Hz.
PAGE_PERIOD = 1 / 32


class TakeNotKept(Exception):
    """A take the person did not keep: ``reason`` is "discarded", "empty" (no input moved
    anything) or "page closed" (before or during the take, or before keeping it)."""

    def __init__(self, reason):
        super().__init__(reason)
        self.reason = reason


@dc.dataclass(frozen=True, eq=False)
class Take:
    """One take: its demonstration, its raw inputs, and the built diagram."""

    demonstration: object
    inputs: InputsLog
    built: object
    master: BrowserMaster
    page_updates: int
    wall_seconds: float
    score: str | None = None  # the drawing's ink against the template (template_score)


def run_take(scenario, *, seed, source="meshcat", visualization=None, duration=None,
             realtime=True, replay_path=None, title="teleoperated take", progress=print,
             on_step=None, scene=True, controls=None, server=None, take_number=None):  # fmt: skip
    """Run one take of the demonstration diagram with a :class:`BrowserMaster`.

    Parameters
    ----------
    scenario : Scenario
    seed : int
        Seeds the sEMG noise (and the unused operator plan).
    source : "meshcat" or InputsLog
        Live inputs from the page of ``visualization``'s Meshcat, or a log to re-drive
        (headless).
    visualization : Visualization, optional
        The live page (needed for ``source="meshcat"``; a new one for a replay of a log):
        the arm (``scenario.visualization``), the page's controls and :class:`TeleopPage`.
    duration : float, optional
        End after this many simulated seconds. With a log, its ``end_time`` is used.
    realtime : bool
        Pace the simulator at real time (``set_target_realtime_rate(1)``).
    replay_path : path-like, optional; title : str
        Record the take in the page's Meshcat and write its HTML replay (with ink for
        drawing), titled ``title``.
    progress : callable taking one line (the master's messages).
    on_step : callable, optional
        Called as ``on_step(t)`` after each page period (tests script the page with it).
    scene : bool
        False leaves out the task's scene (the arm in free space).
    controls : TakeControls, optional
        Live only: the take starts when the page's Start take is clicked (the arm shown at
        its start meanwhile), not before. A page closed before it raises
        :class:`TakeNotKept`.
    server : TeleopPageServer, optional; take_number : int, optional
        Live only: the teleop page's read-outs (state, time, K, activation, force, a slow
        simulation) and the take's number on them.

    Returns
    -------
    Take
    """
    from hemg_drake.diagrams.demonstration import (
        build_demonstration_diagram,
        demonstration_from_logs,
        seed_context,
    )
    from hemg_drake.diagrams.visualization import Visualization
    from hemg_drake.robots.baxter import FLOOR_Z
    from hemg_drake.viz.recording import ReplayRecorder, export_station_replay, frame_task

    live = isinstance(source, str)
    if live and source != "meshcat":
        raise ValueError(f"source must be 'meshcat' or an InputsLog, got {source!r}")
    if live and visualization is None:
        raise ValueError("live inputs need the visualization whose page the person uses")
    if visualization is None and replay_path is not None:
        visualization = Visualization()
    meshcat = None if visualization is None else visualization.meshcat
    if not live:
        duration = source.end_time
    elif duration is not None:
        duration = as_scalar("duration", duration)
    operator = scenario.operator
    holder = {}

    def factory(*, scenario, mapping, p_MS_initial):
        inputs = (
            MeshcatInputs(meshcat, p_MS_initial=p_MS_initial,
                          workspace_size=scenario.master.workspace_size,
                          activation=operator.rest_activation,
                          assist=scenario.assist.mode != "none")  # fmt: skip
            if live
            else LoggedInputs(source.time, source.rows, source.wall_time)
        )
        holder["master"] = BrowserMaster(
            source=inputs, p_MS_initial=p_MS_initial,
            workspace_size=scenario.master.workspace_size,
            hand_stiffness=operator.hand_stiffness, hand_damping=operator.hand_damping,
            max_hand_force=operator.max_hand_force, initial_activation=operator.rest_activation,
        )  # fmt: skip
        return holder["master"]

    built = build_demonstration_diagram(
        scenario, visualization=visualization, operator_factory=factory, scene=scene,
    )  # fmt: skip
    master = holder["master"]
    page = None
    view = frame_task(scenario.task_plan().points)
    if live:
        meshcat.SetCameraPose(*operator_view(scenario.task_plan().points,
                                             built.mapping.master_to_slave))  # fmt: skip
        meshcat.SetTransform("/Grid", RigidTransform([0.0, 0.0, FLOOR_Z]))
        to_W = built.mapping.master_to_slave
        right_W = to_W(np.array([1.0, 0.0, 0.0])) - to_W(np.zeros(3))
        echo_map = np.column_stack([to_W(e) - to_W(np.zeros(3)) for e in np.eye(3)])
        page = TeleopPage(meshcat, k_min=scenario.emg.k_min, k_max=scenario.emg.k_max,
                          server=server, take=take_number,
                          right_W=right_W / np.linalg.norm(right_W), echo_map=echo_map)  # fmt: skip
        if scenario.task == "drawing" and built.scene is not None:
            from hemg_drake.analysis.contact import CONTACT_THRESHOLD

            height = built.scene.paper_height + 5e-4  # as the replay's ink
            page.draw_ink(height, CONTACT_THRESHOLD)
            page.show_template(template_strokes(scenario.task_plan()), height - 2e-4)
    diagram = built.diagram
    simulator = Simulator(diagram)
    seed_context(built, simulator.get_mutable_context(), seed)  # the sEMG noise
    ApplySimulatorConfig(scenario.simulator, simulator)
    simulator.set_target_realtime_rate(1.0 if realtime else 0.0)
    simulator.Initialize()
    context = simulator.get_context()
    station = built.station.diagram
    gain_system = diagram.GetSubsystemByName("variable_gain")
    gain_port = gain_system.get_gain_output_port()
    if live and controls is not None:
        controls.mark_start()
        page.state("waiting")
        # A page opened for an earlier take (or while the scene was built) and closed since
        # counts as closed: the person left, the command does not wait for Enter forever.
        if not controls.wait_start(opened=server is not None and server.opened()):
            raise TakeNotKept("page closed")
        page.state("recording", 0.0)
        # Pace from now: the wait is no part of the take (Simulator's realtime base).
        simulator.ResetStatistics()
    recorder = None
    if replay_path is not None:
        recorder = ReplayRecorder(floor_z=FLOOR_Z, title=title, view=view)
        recorder.start(diagram, meshcat)
    began = time.perf_counter()
    k, reason, t, printed = 0, None, 0.0, 0
    paced = [(0.0, began)]  # (simulated, wall) over the last second: the real-time factor
    activation_port = master.GetOutputPort("activation")
    master_context = master.GetMyContextFromRoot(context)
    assist_ports = _assist_ports(diagram, master) if scenario.assist.mode != "none" else None
    while True:
        k += 1
        t = k * PAGE_PERIOD
        if duration is not None and t >= duration:
            t = duration
        simulator.AdvanceTo(t)
        messages = master.messages(master_context)
        for line in messages[printed:]:
            progress(line)
        printed = len(messages)
        if page is not None:
            station_context = station.GetMyContextFromRoot(context)
            p_WT = built.mapping.master_to_slave(
                master.GetOutputPort("p_MT").Eval(master_context))
            command = master.command(master_context)  # the page's local echo
            echo = None if command is None else (
                built.mapping.master_to_slave(np.array(command[0])), command[1])
            now = time.perf_counter()
            paced.append((t, now))
            while len(paced) > 2 and now - paced[1][1] >= 1.0:
                paced.pop(0)
            rate = (t - paced[0][0]) / max(now - paced[0][1], 1e-9) if now - paced[0][1] > 0.5 else None
            page.update(
                t,
                station.GetOutputPort("p_WE").Eval(station_context),
                station.GetOutputPort("f_WE").Eval(station_context),
                gain_port.Eval(gain_system.GetMyContextFromRoot(context))[0],
                True,
                p_WT,
                activation=activation_port.Eval(master_context)[0],
                rate=rate if realtime else None,
                echo=echo,
                assist=None if assist_ports is None else _assist_values(assist_ports, context),
            )  # fmt: skip
        if on_step is not None:
            on_step(t)
        if duration is not None and t >= duration:
            reason = "duration"
            break
        reason = master.end_reason(master_context)
        if reason is not None and (live or t >= duration):
            break
    wall = time.perf_counter() - began
    demo = demonstration_from_logs(
        built.logger.FindLog(context), built.emg_logger.FindLog(context), seed
    )
    # With the scene the page shows the template: the take's score against it.
    score = None if built.scene is None else template_score(scenario, demo)
    if page is not None:
        page.update(t, np.zeros(3), np.zeros(3), scenario.emg.k_min, False)
        if controls is not None:
            controls.mark_keep()
        page.state("ended", t,
                   hint=None if score is None else f"{score}; K keeps it, D discards it")
    if recorder is not None:
        if page is not None:
            meshcat.Delete(TeleopPage.PATH)  # the page's marks are no part of the replay
        export_station_replay(recorder, built, replay_path, demo.time, demo.p_WE, demo.f_WE)
    times, wall_times, rows = master.inputs_log(master_context)
    log = InputsLog(time=times, wall_time=wall_times, rows=rows, end_time=t,
                    end_reason=reason if live else source.end_reason, seed=seed,
                    scenario=scenario.to_yaml())  # fmt: skip
    return Take(demo, log, built, master, page.updates if page else 0, wall, score)


def _assist_ports(diagram, master):
    """The ports the page shows of the assist: (system, port name) by read-out."""
    intent = diagram.GetSubsystemByName("intent")
    arbitration = diagram.GetSubsystemByName("arbitration")
    return dict(
        weight=(arbitration, "weight"), phase=(intent, "phase"), h=(intent, "h"),
        confidence=(intent, "confidence"), on=(master, "assist_on"),
        link_lost=(arbitration, "link_lost"),
    )  # fmt: skip


def _assist_values(ports, context):
    """The assist's read-outs now (:meth:`TeleopPage.update`'s ``assist``)."""
    values = {}
    for name, (system, port) in ports.items():
        values[name] = system.GetOutputPort(port).Eval(system.GetMyContextFromRoot(context))
    h = values.pop("h")
    return dict(
        weight=float(values["weight"][0]), phase=int(values["phase"][0]), states=len(h),
        belief=float(np.max(h)), confidence=float(values["confidence"][0]),
        on=bool(values["on"][0] >= 0.5), link_lost=bool(values["link_lost"][0] >= 0.5),
    )  # fmt: skip


def _takes_hint(folder):
    return "hemg-drake teleop SCENARIO --out NEW_FOLDER for new takes"


# Keys a take does not read (its length is the person's; the count is demonstrate's):
# scenarios that differ only there record compatible takes.
TAKE_FREE_KEYS = ("duration", "num_demonstrations")


def same_takes(yaml_a, yaml_b):
    """Whether two scenarios (YAML texts) record the same kind of take: equal but for
    :data:`TAKE_FREE_KEYS`."""
    from hemg_drake.scenario import parse_scenario

    def normal(text):
        scenario = parse_scenario(text, source="a dataset's scenario")
        return scenario.replaced(["duration=1.0", "num_demonstrations=1"]).to_yaml()

    return yaml_a == yaml_b or normal(yaml_a) == normal(yaml_b)


def existing_takes(scenario, out_dir):
    """The demonstrations already in ``out_dir/dataset.npz`` and its metadata, checked.

    Returns ``([], {})`` for a folder without a dataset. Raises ValueError if the dataset
    was not finished by a demonstrate/teleop stage, or holds another scenario's takes.
    """
    from hemg_drake.learning.demos import load_dataset
    from hemg_drake.run_folder import RunFolder

    if not (Path(out_dir) / "dataset.npz").exists():
        return [], {}
    folder = RunFolder(out_dir)
    folder.check("demonstrate", folder.dataset, run_hint=_takes_hint(folder))
    demos, metadata = load_dataset(folder.dataset)
    if "scenario" not in metadata or not same_takes(metadata["scenario"], scenario.to_yaml()):
        raise ValueError(
            f"{folder.dataset}: holds demonstrations of another scenario (or other --set "
            "values); give a new --out folder for this one"
        )
    return demos, metadata


def teleop(scenario, out_dir, *, port=7000, duration=None, replay_inputs=None, replays=True,
           progress=print, visualization=None, on_step=None, realtime=True, wait=False,
           page=None):  # fmt: skip
    """Record one take from the browser (or re-drive one from its inputs log) and append it
    to ``out_dir/dataset.npz``, as :func:`hemg_drake.pipeline.demonstrate` writes it.

    The take's demonstration is appended to the dataset (its metadata names each one's
    operator), with ``replay_<c>.html`` (when ``replays``) and its raw inputs
    ``inputs_<c>.npz`` beside it, c its number in the dataset, and the figures redrawn; the
    folder's manifest records the demonstrate stage again, so ``learn`` and ``reproduce``
    take it; an older model and reproduction are replaced (they no longer match). Takes
    already there are kept. The folder is locked for the take and changes only when it is
    saved (:meth:`~hemg_drake.run_folder.RunFolder.transaction`). The demonstration keeps
    the take's active part (:func:`~hemg_drake.teleop_takes.input_span`: idle lead-in and
    lead-out trimmed, the trim said); the inputs log and replay keep the whole take.

    Live (``replay_inputs`` None): without a ``visualization``, one is started, with the
    teleop page (:mod:`hemg_drake.teleop.browser_server`) on ``port``, and the first line
    given to ``progress`` is ``Teleop page: http://localhost:P/ ...``. With ``wait``
    (the CLI's default) the take starts with the page's Start take (Enter), ends with End
    take (Escape) or after ``duration``, and is saved only if the person then clicks Keep
    take (K); Discard take (D), a take where nothing moved, or a page closed before, during
    or after the take raise :class:`TakeNotKept` and write nothing. Without ``wait``
    (scripts) the take starts at once and is kept when it ends (End take or ``duration``;
    a closed page still discards). Ctrl-C (KeyboardInterrupt) discards it: nothing is
    written. With ``replay_inputs`` (a log path): headless, as fast as it runs, the same
    demonstration bit for bit (the log's seed; the scenario must be the log's). ``page`` (a
    :class:`~hemg_drake.teleop.browser_server.TeleopPageServer`) shows the take's state and
    read-outs.

    Returns
    -------
    list of Path, the files written (dataset first).
    """
    from hemg_drake.run_folder import RunFolder

    try:
        with RunFolder.output(out_dir).transaction("demonstrate", keep_own=True) as folder:
            written = _take(scenario, folder, out_dir, duration, replay_inputs, replays,
                            progress, visualization, port, on_step, realtime, wait, page)  # fmt: skip
    except TakeNotKept as error:
        if page is not None:
            said = {"discarded": "discarded", "empty": "nothing moved: not kept",
                    "page closed": "page closed: not kept"}  # fmt: skip
            page.update(state="not kept", headline=said[error.reason], hint="nothing written; "
                        "the next take is being prepared")  # fmt: skip
        raise
    if page is not None:
        page.update(state="saved", headline=f"take {_count(written)}: saved",
                    hint="the next take is being prepared")  # fmt: skip
    return [folder.shown(path) for path in written]


def _count(written):
    """The number of the take just saved: its inputs log's (``inputs_<c>.npz``, the last)."""
    names = [p.name for p in written if p.name.startswith("inputs_")]
    return int(names[-1][len("inputs_"):-len(".npz")]) if names else "?"


def _take(scenario, folder, out_dir, duration, replay_inputs, replays, progress, visualization,
          port, on_step, realtime, wait, page_server):  # fmt: skip
    """One take into ``folder`` (the run's next version, being built; see :func:`teleop`)."""
    from hemg_drake.learning.demos import save_dataset
    from hemg_drake.diagrams.visualization import Visualization
    from hemg_drake.emg.sources import MYO_PERIOD
    from hemg_drake.placements import (
        demonstration_scenario,
        describe_placement,
        has_placements,
        task_frames,
    )
    from hemg_drake.run_folder import RunFolder
    from hemg_drake.teleop.browser_page import TakeControls
    from hemg_drake.teleop_takes import describe_trim, input_span, trim_demonstration
    from hemg_drake.viz.figures import plot_demonstrations, plot_emg_envelopes, save_figure

    demos, metadata = existing_takes(scenario, out_dir)
    c = len(demos) + 1
    controls = None
    if replay_inputs is not None:
        source = load_inputs(replay_inputs)
        if not same_takes(source.scenario, scenario.to_yaml()):
            raise ValueError(
                f"{replay_inputs}: recorded with another scenario (or other --set values) "
                "than the one given"
            )
        seed, operator_name = source.seed, f"browser (replayed from {replay_inputs})"
    else:
        source, seed, operator_name = "meshcat", scenario.seed + c - 1, "browser"
        if visualization is None:
            from hemg_drake.teleop.browser_server import TeleopPageServer

            visualization = Visualization(0)
            page_server = TeleopPageServer(visualization.meshcat, task=scenario.task,
                                           scale=scenario.workspace_mapping().scale, port=port,
                                           assist=scenario.assist.mode)  # fmt: skip
            progress(f"Teleop page: {page_server.url()} (open it in a browser; Meshcat on "
                     f"port {visualization.port()})")  # fmt: skip
        controls = TakeControls(visualization.meshcat) if wait else None
        if wait:
            progress(f"take {c} into {folder.final}/: press Enter in the page to start it "
                     f"(the page's legend lists the keys), {END_KEY} to end it"
                     + (f" (or {duration:g} s)" if duration is not None else "")
                     + "; then K keeps it, D discards it")  # fmt: skip
        else:
            progress(f"take {c} into {folder.final}/: recording; {END_KEY} in the page ends it"
                     + (f" (or {duration:g} s)" if duration is not None else ""))  # fmt: skip
    # With scene.placements each take happens at its own seed's placement, as a simulated
    # demonstration does (the same draw, so a re-driven log lands where it was recorded).
    here = demonstration_scenario(scenario, seed)
    if has_placements(scenario):
        progress(f"take {c}: {describe_placement(here)}")
    replay = folder / f"replay_{c}.html" if replays else None
    title = f"{scenario.task.replace('_', ' ')}: teleoperated take {c}"
    take = run_take(
        here, seed=seed, source=source, visualization=visualization, duration=duration,
        realtime=realtime and replay_inputs is None, replay_path=replay, title=title,
        progress=progress, on_step=on_step, controls=controls, server=page_server,
        take_number=c,
    )  # fmt: skip
    log = take.inputs
    progress(
        f"take {c}: {log.end_time:.2f} s ({log.end_reason}), "
        f"{len(log.time)} input samples, in {take.wall_seconds:.1f} s of wall time"
    )
    if take.score is not None:
        progress(f"take {c}: {take.score}")
    span = input_span(take.master, log.time, log.rows, log.end_time)
    if replay_inputs is None:
        if log.end_reason == "page closed":
            raise TakeNotKept("page closed")
        if span is None and wait:
            raise TakeNotKept("empty")
        if controls is not None and not controls.ask_keep():
            raise TakeNotKept("discarded")
    demo = take.demonstration
    if span is not None:
        progress(describe_trim(c, span, log.end_time))
        demo = trim_demonstration(demo, *span, emg_period=MYO_PERIOD)
    inputs_path = folder / f"inputs_{c}.npz"
    new_files = [p for p in (replay, inputs_path) if p is not None]
    # The takes already recorded stay (the transaction kept them); the model and
    # reproductions, made from the old dataset, do not.
    old_files = [
        folder / name
        for name in RunFolder(out_dir).manifest().get("demonstrate", {}).get("files", {})
        if name.startswith(("replay_", "inputs_")) and (folder / name).is_file()
    ]
    save_inputs(inputs_path, log)
    if not demos or demos[0].frame_A is not None:
        # Each demonstration carries the task frames where it was shown (an older
        # dataset without them keeps none).
        frame_A, frame_b = task_frames(here)
        demo = dc.replace(demo, frame_A=frame_A, frame_b=frame_b)
    if demos and demos[0].q is None:  # an older dataset, without joints: the take keeps none
        demo = dc.replace(demo, q=None, R_WE=None)
    demos = [*demos, demo]
    operators = metadata.get("operators", ["simulated"] * (len(demos) - 1))
    record = dict(
        # The dataset keeps the scenario it was begun with (takes differ only in length).
        scenario=metadata.get("scenario", scenario.to_yaml()), task=scenario.task,
        log_period=scenario.log_period, operators=[*operators, operator_name],
    )  # fmt: skip
    save_dataset(folder.dataset, demos, record)
    figures = [folder / "demonstrations.png", folder / "fig6_emg.png"]
    save_figure(plot_demonstrations(demos, task=scenario.task), figures[0])
    save_figure(plot_emg_envelopes(demos[0].emg, per_channel=scenario.emg.per_channel), figures[1])
    written = [folder.dataset, *sorted(set(old_files) - set(new_files)), *new_files, *figures]
    folder.finish("demonstrate", written, command="teleop")
    return written
