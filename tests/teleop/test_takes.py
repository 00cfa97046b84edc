"""Takes under the person's control: Start, End, Keep or Discard at the page; idle lead-in
and lead-out trimmed; ``hemg-drake takes`` lists and removes takes consistently."""

import dataclasses as dc
import hashlib
import math
import threading
import time

import numpy as np
import pytest

from hemg_drake.cli import main
from hemg_drake.learning.demos import load_dataset
from hemg_drake.run_folder import RunFolder
from hemg_drake.teleop.browser import BrowserMaster
from hemg_drake.teleop.browser_inputs import COLUMNS, END_BUTTON, LoggedInputs, load_inputs
from hemg_drake.teleop.browser_page import DISCARD_BUTTON, KEEP_BUTTON, START_BUTTON
from hemg_drake.teleop_session import TakeNotKept, teleop
from hemg_drake.teleop_takes import active_samples, input_span, trim_demonstration

websocket = pytest.importorskip("websocket", reason="websocket-client is in the dev extra")
msgpack = pytest.importorskip("msgpack")


def row(x=0.0, activation=0.05, axes=None, trigger=math.nan):
    values = dict(zip(COLUMNS, [math.nan] * len(COLUMNS)))
    values.update(slider_x_mm=x, slider_y_mm=0.0, slider_z_mm=0.0, slider_activation=activation)
    values["gamepad_index"] = -1.0 if axes is None else 0.0
    for i, a in enumerate(axes or []):
        values[f"axis_{i}"] = a
    values["button_7"] = trigger
    return [values[c] for c in COLUMNS]


def test_active_samples_and_span_by_hand():
    rows = [row(), row(), row(0.5), row(0.5), row(0.5),
            row(0.5, activation=0.1), row(0.5),  # the activation up, and back: both move
            row(0.5, axes=[0.1, 0, 0, 0]),  # inside the dead zone: idle
            row(0.5, axes=[0.5, 0, 0, 0]), row(0.5, axes=[0, 0, 0, 0], trigger=0.01),
            row(0.5, axes=[0, 0, 0, 0], trigger=0.3), row(0.5)]  # fmt: skip
    master = BrowserMaster(source=LoggedInputs(0.01 * np.arange(len(rows)), rows),
                           p_MS_initial=[0.0, 0.0, 0.0])  # fmt: skip
    # +0.5 mm at the keyboard's 0.25 mm per sample: samples 2 and 3; the trigger's 0.01 is
    # under the slider's 0.05 (the larger counts); the trigger let go at 11 moves it back.
    expected = [False, False, True, True, False, True, True, False, True, False, True, True]
    assert active_samples(master, rows).tolist() == expected
    times = 0.5 * np.arange(len(rows))
    # First active at 1.0 s, last at 5.5 s: 0.2 s before, 1.0 s after (within the end).
    assert input_span(master, times, rows, 6.0) == pytest.approx((0.8, 6.0))
    assert input_span(master, times, rows, 9.0) == pytest.approx((0.8, 6.5))
    assert input_span(master, times, [row()] * 5, 2.0) is None


def _demo(n=101, emg_per=2):
    from hemg_drake.learning.demos import Demonstration

    t = 0.01 * np.arange(n)
    ramp = np.linspace(0, 1, n)
    e = n * emg_per - 1
    return Demonstration(
        seed=1, time=t, p_WE=np.column_stack([ramp, 2 * ramp, 3 * ramp]), v_WE=np.zeros((n, 3)),
        p_MS=np.zeros((n, 3)), envelope=ramp, activation=ramp, gain=ramp, f_WE=np.zeros((n, 3)),
        p_WE_desired=np.zeros((n, 3)), emg_time=0.005 * np.arange(e),
        emg=np.arange(e * 8, dtype=float).reshape(e, 8), muscle_activation=np.arange(e) / e,
    )  # fmt: skip


def test_trim_keeps_the_span_and_restarts_the_clock():
    demo = _demo()
    cut = trim_demonstration(demo, 0.204, 0.5, emg_period=0.005)
    # Log samples 0.21 .. 0.50 s (30), their clock from 0; sEMG samples 42 .. 100.
    assert len(cut) == 30 and cut.time[0] == 0.0
    np.testing.assert_allclose(cut.time, 0.01 * np.arange(30), atol=1e-12)
    np.testing.assert_array_equal(cut.p_WE, demo.p_WE[21:51])
    np.testing.assert_array_equal(cut.emg, demo.emg[42:101])
    np.testing.assert_allclose(cut.emg_time, 0.005 * np.arange(59), atol=1e-12)
    np.testing.assert_array_equal(cut.muscle_activation, demo.muscle_activation[42:101])


class Clicker:
    """Clicks a page button over the websocket every 0.1 s (wall) while ``when()`` holds:
    a person pressing a key until the page reacts."""

    def __init__(self, meshcat):
        self.ws = websocket.create_connection(meshcat.ws_url(), timeout=5)
        self.plan, self.stop = [], threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        while not self.stop.is_set():
            for name, when in self.plan:
                if when():
                    self.ws.send_binary(msgpack.packb({"type": "button", "name": name}))
            time.sleep(0.1)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join()
        self.ws.close()


def _hash(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize("answer", ["keep", "discard"])
def test_a_take_waits_for_start_and_is_saved_only_when_kept(scenario, meshcat, visualization,
                                                            tmp_path, answer):  # fmt: skip
    from hemg_drake.teleop.browser_inputs import SLIDER_X

    started, ended = [], []

    def on_step(t):
        if not started:
            started.append(time.monotonic())
        if t >= 0.4:
            meshcat.SetSliderValue(SLIDER_X, 6.0)  # the person moves, then waits
        if t >= 2.0 and not ended:
            ended.append(t)

    lines = []
    with Clicker(meshcat) as clicker:
        began = time.monotonic()
        clicker.plan = [
            (START_BUTTON, lambda: time.monotonic() - began > 1.0 and not started),
            (END_BUTTON, lambda: bool(ended)),
            (KEEP_BUTTON if answer == "keep" else DISCARD_BUTTON, lambda: bool(ended)),
        ]
        run = lambda: teleop(scenario, tmp_path, visualization=visualization, duration=20.0,  # noqa: E731
                             replays=False, realtime=False, wait=True, progress=lines.append,
                             on_step=on_step)  # fmt: skip
        if answer == "discard":
            with pytest.raises(TakeNotKept, match="discarded"):
                run()
            assert not (tmp_path / "dataset.npz").exists() and not list(tmp_path.iterdir())
            return
        try:
            run()
        except TakeNotKept:
            print(lines)
            raise
    # Nothing happened before Start (clicked after a wall-clock second of waiting).
    assert started[0] - began > 0.9
    demos, _ = load_dataset(tmp_path / "dataset.npz")
    log = load_inputs(tmp_path / "inputs_1.npz")
    assert log.end_reason == "button" and log.time[0] == 0.0, lines
    # The slider jumped 6 mm at 0.40 s and nothing after it; the target followed at
    # 0.25 mm per sample, its last step at 0.40 + 0.23 s: kept 0.20 .. 1.63 s.
    first = log.time[np.flatnonzero(log.rows[:, COLUMNS.index("slider_x_mm")] == 6.0)[0]]
    assert first == pytest.approx(0.40, abs=0.011)
    assert demos[0].time[-1] == pytest.approx(1.43, abs=0.011)
    assert any("trimmed" in line and "lead-in" in line for line in lines), lines


def test_a_take_where_nothing_moved_or_the_page_closed_is_not_kept(scenario, meshcat,
                                                                  visualization, tmp_path):  # fmt: skip
    with Clicker(meshcat) as clicker:
        clicker.plan = [(START_BUTTON, lambda: True), (END_BUTTON, lambda: True)]
        with pytest.raises(TakeNotKept, match="empty"):
            teleop(scenario, tmp_path, visualization=visualization, duration=20.0, replays=False,
                   realtime=False, wait=True, progress=lambda line: None)  # fmt: skip
    # The only page closes while the person is asked to start: nothing kept, nothing waits on.
    ws = websocket.create_connection(meshcat.ws_url(), timeout=5)
    threading.Timer(0.5, ws.close).start()
    with pytest.raises(TakeNotKept, match="page closed"):
        teleop(scenario, tmp_path, visualization=visualization, duration=20.0, replays=False,
               realtime=False, wait=True, progress=lambda line: None)  # fmt: skip
    assert not list(tmp_path.iterdir())


def test_takes_lists_and_removes_a_take_keeping_the_folder_consistent(tmp_path, capsys):
    out = tmp_path / "run"
    base = ["teleop", "cotter_pin", "--out", str(out), "--port", "0", "--no-replay", "--no-wait"]
    for duration in ("0.1", "0.2", "0.3"):
        assert main([*base, "--duration", duration]) == 0
    assert main(["learn", str(out), "--set", "learning.num_states=2"]) == 0
    third = _hash(out / "inputs_3.npz")
    before, _ = load_dataset(out / "dataset.npz")
    capsys.readouterr()
    assert main(["takes", str(out)]) == 0
    listed = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in listed] == ["1", "2", "3"]
    assert "inputs_2.npz" in listed[1] and "browser" in listed[1]
    assert main(["takes", str(out), "--remove", "2"]) == 0
    after, metadata = load_dataset(out / "dataset.npz")
    assert [len(d) for d in after] == [len(before[0]), len(before[2])]
    for field in dc.fields(after[1]):
        a, b = getattr(after[1], field.name), getattr(before[2], field.name)
        assert (a is None and b is None) or np.array_equal(a, b)
    assert metadata["operators"] == ["browser", "browser"]
    assert _hash(out / "inputs_2.npz") == third and not (out / "inputs_3.npz").exists()
    assert not (out / "model.npz").exists()  # made from the older dataset: gone with it
    folder = RunFolder(out)
    for name in ("dataset.npz", "inputs_1.npz", "inputs_2.npz", "demonstrations.png"):
        folder.check("demonstrate", out / name, run_hint="x")
    assert folder.takes()
    # Bad input: one line, nothing changed.
    snapshot = {p.name: _hash(p) for p in out.iterdir() if p.is_file()}
    for argv, said in ((["takes", str(out), "--remove", "5"], "holds takes 1..2"),
                       (["takes", str(tmp_path / "none")], "not found"),
                       (["takes", str(out), "--remove", "0"], "--remove")):  # fmt: skip
        capsys.readouterr()
        try:
            code = main(argv)
        except SystemExit as exit:  # argparse's own one-line error
            code = exit.code
        assert code == 2
        err = capsys.readouterr().err.strip()
        assert said in err and len(err.splitlines()) == 1, err
    assert {p.name: _hash(p) for p in out.iterdir() if p.is_file()} == snapshot


class _Buttons:
    """Meshcat's buttons as TakeControls reads them: click counts and one open page."""

    def __init__(self):
        self.clicks = {}

    def GetButtonNames(self):
        return list(self.clicks)

    def AddButton(self, name, keycode=None):
        self.clicks[name] = 0

    def GetButtonClicks(self, name):
        return self.clicks[name]

    def GetNumActiveConnections(self):
        return 1


@pytest.mark.timeout(120)
def test_a_page_closed_between_takes_ends_the_wait_for_enter(scenario, meshcat, visualization,
                                                            tmp_path):  # fmt: skip
    """A person who discards a take (or keeps one of several) and closes the tab before the
    next take asks for Enter has left: the wait ends as for a page closed while asked (it
    once waited for ever, the page never connecting again)."""
    import urllib.request

    from hemg_drake.teleop.browser_server import TeleopPageServer

    server = TeleopPageServer(meshcat, task="cotter_pin", scale=2.0)
    try:
        assert not server.opened()
        urllib.request.urlopen(server.url(), timeout=10).read()  # loaded, then gone
        assert server.opened()
        began = time.monotonic()
        with pytest.raises(TakeNotKept, match="page closed"):
            teleop(scenario, tmp_path, visualization=visualization, duration=20.0,
                   replays=False, realtime=False, wait=True, progress=lambda line: None,
                   page=server)  # fmt: skip
        assert time.monotonic() - began < 30.0
        assert not list(tmp_path.iterdir())
    finally:
        server.close()


def test_an_enter_pressed_while_the_scene_is_built_starts_the_first_take():
    """The Start button is on the page from TakeControls' creation; a press then, before the
    session marks and asks for it, starts the first take (it was once dropped: a flaky
    first Enter in the page's test). A later take counts only clicks from its own mark."""
    from hemg_drake.teleop.browser_page import START_BUTTON, TakeControls

    buttons = _Buttons()
    polls = []

    def sleep(_):  # a page that never clicks again: give up after a few polls
        polls.append(1)
        if len(polls) > 5:
            raise TimeoutError("Start was never seen")

    controls = TakeControls(buttons, sleep=sleep)
    buttons.clicks[START_BUTTON] += 1  # the person presses Enter while the scene is built
    controls.mark_start()
    assert controls.wait_start() and not polls
    # The second take: the first one's click does not start it.
    controls.mark_start()
    with pytest.raises(TimeoutError):
        controls.wait_start()


def _take_along(template, moved=None, shift=(0.0, 0.0)):
    """A drawing demonstration inking each template stroke at 1 mm spacing along its
    waypoints, 2 N on the pen, 0.3 s in the air before each; ``moved`` = (stroke, dx): that
    stroke's middle waypoint moved dx (m) along x and the whole stroke by ``shift`` (m)."""
    from hemg_drake.learning.demos import Demonstration

    points, force = [], []
    for k, stroke in enumerate(template):
        corners = np.array(stroke, dtype=float)
        if moved is not None and k == moved[0]:
            corners = corners + [shift[0], shift[1], 0.0]
            corners[len(corners) // 2, 0] += moved[1]
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(corners, axis=0), axis=1))])
        along = np.linspace(0.0, s[-1], max(20, int(s[-1] / 1e-3)))
        ink = np.column_stack([np.interp(along, s, c) for c in corners.T])
        points += [np.repeat(ink[:1] + [0.0, 0.0, 0.01], 30, axis=0), ink]
        force += [np.zeros((30, 3)), np.tile([0.0, 0.0, 2.0], (len(ink), 1))]
    p, f = np.vstack(points), np.vstack(force)
    n = len(p)
    t = np.arange(n) * 0.01
    return Demonstration(
        seed=1, time=t, p_WE=p, v_WE=np.gradient(p, t, axis=0), p_MS=p, p_WE_desired=p,
        envelope=np.zeros(n), activation=np.zeros(n), gain=np.full(n, 100.0), f_WE=f,
        emg_time=np.arange(2 * n) * 0.005, emg=np.zeros((2 * n, 8)),
        muscle_activation=np.zeros(2 * n),
    )  # fmt: skip


def _shapes_of(line):
    drawn, shapes = line.split(" for the template's 3, ")
    return drawn, [float(e) for e in shapes.removesuffix(" mm off in shape").split(" / ")]


def test_a_drawing_take_is_scored_against_the_template_the_page_shows():
    import dataclasses as dc

    from hemg_drake.scenario import load_scenario, shipped_scenario
    from hemg_drake.teleop_takes import template_score, template_strokes

    scenario = load_scenario(shipped_scenario("drawing"))
    template = template_strokes(scenario.task_plan())
    assert len(template) == 3
    # As drawn: next to nothing (the 1 mm sampling cuts the corners).
    drawn, errors = _shapes_of(template_score(scenario, _take_along(template)))
    assert drawn == "3 ink strokes" and max(errors) <= 0.2, errors
    # The second stroke's middle waypoint 4 mm off shows in its shape; the same stroke also
    # moved 3 mm sideways scores the same (placement is not shape).
    _, moved = _shapes_of(template_score(scenario, _take_along(template, (1, 0.004))))
    _, shifted = _shapes_of(template_score(scenario, _take_along(template, (1, 0.004),
                                                                 shift=(0.0, 0.003))))  # fmt: skip
    assert 0.5 < moved[1] < 2.0 and shifted == moved, (moved, shifted)
    assert moved[0] <= 0.2 and moved[2] <= 0.2
    take = _take_along(template)
    assert template_score(scenario, dc.replace(take, f_WE=0 * take.f_WE)) == "no ink"
    # A trace that cannot be scored says why, and costs nothing else.
    stalled = take.time.copy()
    stalled[5] = stalled[4]
    assert template_score(scenario, dc.replace(take, time=stalled)) == (
        "not scored (times must be strictly increasing)")
    assert template_score(load_scenario(shipped_scenario("cotter_pin")), take) is None


def test_takes_lists_each_drawing_take_with_its_score(tmp_path, capsys):
    from hemg_drake.learning.demos import save_dataset
    from hemg_drake.scenario import load_scenario, shipped_scenario
    from hemg_drake.teleop_takes import template_strokes

    scenario = load_scenario(shipped_scenario("drawing"))
    template = template_strokes(scenario.task_plan())
    out = tmp_path / "run"
    with RunFolder.output(out).transaction("demonstrate", keep_own=True) as folder:
        record = dict(scenario=scenario.to_yaml(), task="drawing", log_period=0.01,
                      operators=["browser", "browser"])  # fmt: skip
        save_dataset(folder.dataset, [_take_along(template), _take_along(template, (1, 0.004))],
                     record)  # fmt: skip
        folder.finish("demonstrate", [folder.dataset], command="teleop")
    capsys.readouterr()
    assert main(["takes", str(out)]) == 0
    listed = capsys.readouterr().out.splitlines()
    scores = [_shapes_of(line.split("  (")[1].rstrip(")")) for line in listed]
    assert [drawn for drawn, _ in scores] == ["3 ink strokes", "3 ink strokes"], listed
    assert max(scores[0][1]) <= 0.2 and scores[1][1][1] > 0.5, listed  # the moved waypoint


def test_a_replayed_drawing_take_carries_its_score():
    """The score is made where the take ends (run_take), before the page asks K or D."""
    from hemg_drake.scenario import load_scenario, shipped_scenario
    from hemg_drake.teleop.browser_inputs import InputsLog
    from hemg_drake.teleop_session import run_take

    scenario = load_scenario(shipped_scenario("drawing"))
    times = np.arange(30) * 0.01
    log = InputsLog(time=times, wall_time=times, rows=np.array([row()] * 30), end_time=0.3,
                    end_reason="button", seed=1, scenario=scenario.to_yaml())  # fmt: skip
    take = run_take(scenario, seed=1, source=log, realtime=False)
    assert take.score == "no ink"  # the pen in the air where the take starts
