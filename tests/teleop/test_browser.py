"""The browser master: its laws against hand computation, and every input path on loopback.

Inputs reach Meshcat three ways here, as a person's would: Meshcat's Python API
(``SetSliderValue``, the keyboard's sliders), msgpack messages on Meshcat's websocket as
the page sends them (gamepad, button clicks; the layout of Drake's
``geometry/meshcat_types_internal.h`` ``UserInterfaceEvent``), and real key presses in the
page in headless Chromium.
"""

import dataclasses as dc
import math

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from hemg_drake.teleop.browser import BrowserMaster, dead_zone
from hemg_drake.teleop.browser_inputs import (
    COLUMNS, END_BUTTON, SLIDER_ACTIVATION, SLIDER_X, LoggedInputs, load_inputs,
)  # fmt: skip
from hemg_drake.teleop_session import run_take

websocket = pytest.importorskip("websocket", reason="websocket-client is in the dev extra")
msgpack = pytest.importorskip("msgpack")

P0 = [0.01, -0.02, 0.03]
HALF = [0.08, 0.06, 0.06]  # the Touch X's box, half sizes (m)
K_H, D_H, F_MAX = 300.0, 5.0, 15.0


def row(slider_mm=(0.0, 0.0, 0.0), activation=0.05, axes=None, buttons=None, clicks=0, pages=0):
    """One raw input row; ``axes``/``buttons`` None: no gamepad."""
    values = dict(zip(COLUMNS, [math.nan] * len(COLUMNS)))
    values.update(slider_x_mm=slider_mm[0], slider_y_mm=slider_mm[1], slider_z_mm=slider_mm[2])
    values.update(slider_activation=activation, end_clicks=clicks, connections=pages)
    values["gamepad_index"] = -1.0 if axes is None else 0.0
    for i, value in enumerate(axes or []):
        values[f"axis_{i}"] = value
    for i, value in enumerate(buttons or []):
        values[f"button_{i}"] = value
    return [values[name] for name in COLUMNS]


def master_after(rows, p_MS, v_MS, **parameters):
    """The BrowserMaster fed ``rows`` at 0, 10, 20 ms ..., its context and outputs just after
    the last."""
    times = 0.01 * np.arange(len(rows))
    master = BrowserMaster(source=LoggedInputs(times, rows), p_MS_initial=P0, **parameters)
    simulator = Simulator(master)
    context = simulator.get_mutable_context()
    master.GetInputPort("p_MS").FixValue(context, p_MS)
    master.GetInputPort("v_MS").FixValue(context, v_MS)
    master.GetInputPort("feedback_force").FixValue(context, [0.0, 0.0, 0.0])
    simulator.AdvanceTo(times[-1] + 0.005)
    force = master.GetOutputPort("hand_force").Eval(context)
    activation = master.GetOutputPort("activation").Eval(context)[0]
    return master, context, force, activation


def test_dead_zone_by_hand():
    assert dead_zone(0.1, 0.15) == 0.0
    assert dead_zone(-0.15, 0.15) == 0.0
    assert dead_zone(0.575, 0.15) == pytest.approx(0.5)
    assert dead_zone(-1.0, 0.15) == pytest.approx(-1.0)
    assert dead_zone(1.7, 0.15) == pytest.approx(1.0)
    assert dead_zone(math.nan, 0.15) == 0.0


def test_keyboard_and_gamepad_target_and_hand_force_by_hand():
    # Samples 0..3: the keyboard moves x by +4 mm (relative to sample 0) and z by -6 mm;
    # the gamepad holds left stick x at 0.575 (0.5 beyond the dead zone: 0.05 m/s) and the
    # right stick y at -1 (up: +0.1 m/s in y) from sample 1 on.
    pad = dict(axes=[0.575, 0.0, 0.0, -1.0], buttons=[0.0] * 7 + [0.3])
    rows = [
        row((10.0, 0.0, 0.0)),
        row((12.0, 0.0, -2.0), **pad),
        row((14.0, 0.0, -6.0), **pad),
        row((14.0, 0.0, -6.0), **pad),
    ]
    p_MS, v_MS = [0.0, 0.0, 0.0], [0.01, 0.0, -0.02]
    # (key_speed above any step here: the keyboard's speed limit is tested on its own.)
    _, _, force, activation = master_after(rows, p_MS, v_MS, key_speed=10.0)
    # Target: start + keyboard offset + three gamepad samples of T * v.
    p_T = [0.01 + 0.004 + 3 * 0.01 * 0.05, -0.02 + 3 * 0.01 * 0.1, 0.03 - 0.006]
    v_T = [0.05, 0.1, 0.0]
    expected = [K_H * (p_T[i] - p_MS[i]) + D_H * (v_T[i] - v_MS[i]) for i in range(3)]
    np.testing.assert_allclose(force, expected, rtol=1e-12, atol=1e-12)
    assert activation == pytest.approx(0.3)  # the trigger beats the slider's 0.05


def test_target_stays_in_the_workspace_and_hand_force_saturates():
    # Full stick to the right for 120 samples (0.12 m of travel at 0.1 m/s) from x = 0.01:
    # the target stops at the wall x = 0.08, with no velocity once it is there.
    pad = dict(axes=[1.0, 0.0, 0.0, 0.0], buttons=[0.0] * 8)
    rows = [row()] + [row(**pad)] * 120
    p_T = [HALF[0], P0[1], P0[2]]
    expected = [K_H * (p_T[i] - P0[i]) for i in range(3)]  # 21 N along x
    _, _, force, _ = master_after(rows, P0, [0.0, 0.0, 0.0], max_hand_force=1000.0)
    np.testing.assert_allclose(force, expected, rtol=1e-12, atol=1e-12)
    # With the default 15 N limit, the same push saturates in norm.
    _, _, force, _ = master_after(rows, P0, [0.0, 0.0, 0.0])
    norm = math.sqrt(sum(f * f for f in expected))
    np.testing.assert_allclose(force, [f * F_MAX / norm for f in expected], rtol=1e-12)


def test_missing_or_nan_gamepad_moves_nothing_and_is_reported():
    rows = [
        row(),
        row(axes=[math.nan, 0.0, 0.0, math.nan], buttons=[0.0] * 7 + [math.nan]),
        row(axes=[0.0] * 4, buttons=[0.0] * 8),
        row(activation=0.4),  # the page stopped sending the gamepad
    ]
    master, context, force, activation = master_after(rows, P0, [0.0, 0.0, 0.0])
    np.testing.assert_allclose(force, [0.0, 0.0, 0.0], atol=1e-15)
    assert activation == pytest.approx(0.4)
    messages = " | ".join(master.messages(context))
    assert "gamepad 0 connected" in messages and "NaN" in messages
    assert "disconnected" in messages


def test_nan_slider_holds_its_axis():
    rows = [row((4.0, 0.0, 0.0)), row((8.0, math.nan, 0.0)), row((math.nan, 2.0, 0.0)),
            row((math.nan, 2.0, 0.0))]  # fmt: skip
    _, _, force, _ = master_after(rows, P0, [0.0, 0.0, 0.0], key_speed=10.0)
    # x holds its last finite offset (+4 mm), y moved +2 mm, z did not move.
    np.testing.assert_allclose(force, [K_H * 0.004, K_H * 0.002, 0.0], rtol=1e-9, atol=1e-12)
    # A first sample that is NaN: the zero is taken where the target is when it turns finite.
    rows = [row((math.nan, 0.0, 0.0)), row((30.0, 0.0, 0.0)), row((36.0, 0.0, 0.0))]
    _, _, force, _ = master_after(rows, P0, [0.0, 0.0, 0.0], key_speed=10.0)
    np.testing.assert_allclose(force, [K_H * 0.006, 0.0, 0.0], rtol=1e-9, atol=1e-12)


def test_keyboard_target_moves_at_no_more_than_key_speed():
    """A slider that jumps (keys moved on while the simulation stalled) is followed at
    key_speed, sample by sample: 0.025 m/s is 0.25 mm per 10 ms sample, per axis."""
    rows = [row((0.0, 0.0, 0.0)), row((10.0, -0.1, 0.0))] + [row((10.0, -0.1, 0.0))] * 3
    # Four samples after the jump: x has moved 4 x 0.25 mm = 1 mm of its 10, y its 0.1 mm.
    _, _, force, _ = master_after(rows, P0, [0.0, 0.0, 0.0], key_speed=0.025)
    np.testing.assert_allclose(force, [K_H * 0.001, -K_H * 0.0001, 0.0], rtol=1e-9, atol=1e-12)
    rows += [row((10.0, -0.1, 0.0))] * 40  # and it gets there, then stays
    _, _, force, _ = master_after(rows, P0, [0.0, 0.0, 0.0], key_speed=0.025)
    np.testing.assert_allclose(force, [K_H * 0.010, -K_H * 0.0001, 0.0], rtol=1e-9, atol=1e-12)


def test_left_bumper_moves_the_sticks_at_a_quarter_speed():
    """The gamepad's fine motion, as Shift: button 4 held (> 0.5) scales the sticks' speed
    by 0.25; 0.5 or NaN does not."""
    pad = dict(axes=[1.0, 0.0, 0.0, -1.0], buttons=[0.0] * 4 + [1.0] + [0.0] * 3)
    rows = [row()] + [row(**pad)] * 4
    _, _, force, _ = master_after(rows, P0, [0.0, 0.0, 0.0], max_hand_force=1000.0)
    # Four samples of 10 ms at 0.25 x 0.1 m/s in x and y: 1 mm each; v_T = 0.025 m/s.
    expected = [K_H * 0.001 + D_H * 0.025, K_H * 0.001 + D_H * 0.025, 0.0]
    np.testing.assert_allclose(force, expected, rtol=1e-9, atol=1e-12)
    for held in (0.5, math.nan):
        pad["buttons"][4] = held
        rows = [row()] + [row(**pad)] * 4
        _, _, force, _ = master_after(rows, P0, [0.0, 0.0, 0.0], max_hand_force=1000.0)
        np.testing.assert_allclose(force, [K_H * 0.004 + D_H * 0.1] * 2 + [0.0], rtol=1e-9)


def test_command_is_where_the_newest_sample_sends_the_target():
    """The page's local echo starts from ``command``: the keyboard's set-point plus the
    gamepad's part, the newest sample's sliders, while the target is still on its way (at
    key_speed, 0.25 mm per sample)."""
    rows = [row((10.0, 0.0, 0.0)), row((13.0, 0.0, -1.0)),
            row((13.0, 0.0, -1.0), axes=[1.0, 0.0, 0.0, 0.0], buttons=[0.0] * 8)]  # fmt: skip
    master, context, _, _ = master_after(rows, P0, [0.0, 0.0, 0.0])
    p_MC, sliders = master.command(context)
    # Set-point: P0 + (3, 0, -1) mm; gamepad: one sample of 0.1 m/s in x (1 mm).
    np.testing.assert_allclose(p_MC, [P0[0] + 0.003 + 0.001, P0[1], P0[2] - 0.001], atol=1e-15)
    assert sliders == [13.0, 0.0, -1.0]
    # The target itself: two samples of at most 0.25 mm on x's keyboard part (+ 1 mm pad).
    p_T = master.GetOutputPort("p_MT").Eval(context)
    np.testing.assert_allclose(p_T, [P0[0] + 0.0005 + 0.001, P0[1], P0[2] - 0.0005], atol=1e-15)
    fresh = BrowserMaster(source=LoggedInputs([0.0], [row()]), p_MS_initial=P0)
    assert fresh.command(fresh.CreateDefaultContext()) is None  # nothing sampled yet


def test_two_contexts_hold_independent_logs_and_a_clone_samples_the_same():
    """Everything the master samples lives in its Context: two contexts of one diagram (and
    a Clone() of the diagram, or of a context) run apart without sharing a sample."""
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    # Sample 0 without a gamepad, then the left stick at 0.575 (0.05 m/s in x), and a page
    # open from sample 2 on.
    pad = dict(axes=[0.575, 0.0, 0.0, 0.0], buttons=[0.0] * 8)
    rows = [row(), row(**pad)] + [row(pages=1, **pad)] * 8
    times, walls = 0.01 * np.arange(len(rows)), 100.0 + 0.5 * np.arange(len(rows))
    builder = DiagramBuilder()
    master = builder.AddSystem(BrowserMaster(source=LoggedInputs(times, rows, walls),
                                             p_MS_initial=P0))  # fmt: skip
    for name, value in (("p_MS", P0), ("v_MS", [0.0] * 3), ("feedback_force", [0.0] * 3)):
        source = builder.AddSystem(ConstantVectorSource(value))
        builder.Connect(source.get_output_port(), master.GetInputPort(name))
    builder.ExportOutput(master.GetOutputPort("hand_force"), "hand_force")
    diagram = builder.Build()

    def run(system, context, t):
        simulator = Simulator(system, context)
        simulator.AdvanceTo(t)
        return simulator.get_context()

    def force_x(n):  # n samples taken: (n - 1) samples of 0.5 mm in x, v_T = 0.05 m/s
        return K_H * (n - 1) * 0.0005 + (D_H * 0.05 if n >= 2 else 0.0)

    def expect(system, context, n):
        sub = system.GetMyContextFromRoot(context)
        t, wall, logged = system.inputs_log(sub)
        np.testing.assert_array_equal(t, times[:n])
        np.testing.assert_array_equal(wall, walls[:n])
        np.testing.assert_array_equal(logged, np.array(rows[:n]))
        hand = diagram.GetOutputPort("hand_force").Eval(context)
        assert hand[0] == pytest.approx(force_x(n), rel=1e-12)
        np.testing.assert_allclose(hand[1:], 0.0, atol=1e-15)

    a = run(diagram, diagram.CreateDefaultContext(), 0.055)  # samples at 0 .. 50 ms
    b = run(diagram, diagram.CreateDefaultContext(), 0.025)  # 0 .. 20 ms
    expect(master, a, 6)
    expect(master, b, 3)
    assert master.messages(b) == master.messages(a) == ("t = 0.01 s: gamepad 0 connected",)
    assert master.end_reason(master.GetMyContextFromRoot(a)) is None
    # A copy of context a advanced further leaves a as it was.
    c = run(diagram, a.Clone(), 0.085)
    expect(master, c, 9)
    expect(master, a, 6)
    # Clone() of the diagram (double -> double): the same samples, bit for bit; the clone
    # reads the same (read-only) source.
    clone = diagram.Clone()
    clone_master = clone.GetSubsystemByName(master.get_name())
    assert clone_master.source is master.source
    d = run(clone, clone.CreateDefaultContext(), 0.055)
    for mine, theirs in zip(master.inputs_log(master.GetMyContextFromRoot(a)),
                            clone_master.inputs_log(clone_master.GetMyContextFromRoot(d))):
        np.testing.assert_array_equal(mine, theirs)
    np.testing.assert_array_equal(
        clone.GetOutputPort("hand_force").Eval(d), diagram.GetOutputPort("hand_force").Eval(a)
    )
    # ToAutoDiffXd: the hand force's derivative in p_MS is -K_h (unsaturated), by hand.
    from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, InitializeAutoDiff
    from pydrake.systems.analysis import Simulator_

    ad = master.ToAutoDiffXd()
    e = ad.CreateDefaultContext()
    ad.GetInputPort("p_MS").FixValue(e, InitializeAutoDiff(np.array(P0)).ravel())
    for name in ("v_MS", "feedback_force"):
        ad.GetInputPort(name).FixValue(e, [AutoDiffXd(0.0)] * 3)
    simulator = Simulator_[AutoDiffXd](ad, e)
    simulator.AdvanceTo(0.025)
    hand = ad.GetOutputPort("hand_force").Eval(e)
    assert hand[0].value() == pytest.approx(force_x(3), rel=1e-12)
    np.testing.assert_allclose(ExtractGradient(hand), -K_H * np.eye(3), rtol=1e-12)
    # A log that ends before the diagram asks: refused, naming the times.
    with pytest.raises(ValueError, match="ends at t = 0.090"):
        run(diagram, diagram.CreateDefaultContext(), 0.15)


def test_bad_arguments_and_logs_are_refused(tmp_path):
    with pytest.raises(ValueError, match="p_MS_initial"):
        BrowserMaster(source=LoggedInputs([0.0], [row()]), p_MS_initial=[0.2, 0.0, 0.0])
    with pytest.raises(ValueError, match="source"):
        BrowserMaster(source=None, p_MS_initial=P0)
    with pytest.raises(ValueError, match="shape"):
        LoggedInputs([0.0], [[0.0, 1.0]])
    inputs = LoggedInputs([0.0, 0.02], [row(), row()])
    inputs.read(0.0)
    with pytest.raises(ValueError, match="t = 0.02"):
        inputs.read(0.01)
    bad = tmp_path / "inputs.npz"
    bad.write_bytes(b"PK\x03\x04 not really")
    with pytest.raises(ValueError, match="teleop inputs log"):
        load_inputs(bad)


def test_keyboard_sliders_move_the_stylus_and_the_log_replays_bit_for_bit(
    scenario, meshcat, visualization
):
    # Meshcat's Python API stands in for the key presses: +10 mm in x from t = 0.25 s.
    def script(t):
        if t >= 0.25:
            meshcat.SetSliderValue(SLIDER_X, 10.0)
            meshcat.SetSliderValue(SLIDER_ACTIVATION, 0.9)

    # In free space (no pin holding the tool), so the stylus settles on the target.
    take = run_take(scenario, seed=3, visualization=visualization, duration=0.75, realtime=False,
                    on_step=script, progress=lambda line: None, scene=False)  # fmt: skip
    demo, log = take.demonstration, take.inputs
    p0 = take.master.p_MS_initial
    assert demo.p_MS[-1, 0] - p0[0] == pytest.approx(0.010, abs=2e-4)
    np.testing.assert_allclose(demo.p_MS[-1, 1:], p0[1:], atol=1e-6)
    # The slave is asked to move scale x R_WM [10 mm, 0, 0].
    mapping = take.built.mapping
    expected = mapping.master_to_slave(np.array(p0) + [0.010, 0.0, 0.0])
    np.testing.assert_allclose(demo.p_WE_desired[-1], expected, atol=5e-4)
    assert demo.muscle_activation[-1] == pytest.approx(0.9)
    assert demo.gain[-1] > demo.gain[0]
    # Inputs at 100 Hz; the same diagram re-driven from them is the same, bit for bit.
    assert len(log.time) == 75 and np.all(np.diff(log.time) > 0)
    again = run_take(scenario, seed=3, source=log, realtime=False, scene=False)
    for field in dc.fields(demo):
        assert np.array_equal(getattr(demo, field.name), getattr(again.demonstration, field.name))
    for name in ("time", "wall_time", "rows", "end_time"):  # NaN: no gamepad
        assert np.array_equal(getattr(log, name), getattr(again.inputs, name), equal_nan=True)
    assert (log.seed, log.scenario) == (again.inputs.seed, again.inputs.scenario)
    # A Clone() of the demonstration diagram, re-driven by the same log from its own context
    # (the seed's, the arm at its start), gives the same demonstration and log again.
    from pydrake.systems.analysis import ApplySimulatorConfig

    from hemg_drake.diagrams.demonstration import demonstration_from_logs, initial_context

    built = again.built
    clone = built.diagram.Clone()
    simulator = Simulator(clone, initial_context(built, 3, diagram=clone))
    ApplySimulatorConfig(scenario.simulator, simulator)
    simulator.AdvanceTo(log.end_time)
    context = simulator.get_context()
    logs = [clone.GetSubsystemByName(sink.get_name()).FindLog(context)
            for sink in (built.logger, built.emg_logger)]  # fmt: skip
    cloned = demonstration_from_logs(*logs, 3)
    for field in dc.fields(demo):
        assert np.array_equal(getattr(demo, field.name), getattr(cloned, field.name))
    master = clone.GetSubsystemByName(take.master.get_name())
    for mine, theirs in zip((log.time, log.wall_time, log.rows),
                            master.inputs_log(master.GetMyContextFromRoot(context))):
        assert np.array_equal(mine, theirs, equal_nan=True)


def send(ws, **message):
    ws.send_binary(msgpack.packb(message))


def test_gamepad_and_button_over_the_websocket(scenario, meshcat, visualization):
    """Gamepad axes, the trigger, a NaN axis, a disconnect and the End button, as the page
    sends them."""
    ws = websocket.create_connection(meshcat.ws_url(), timeout=5)
    sent = {}

    def script(t):
        stage = int(t / 0.125)
        if stage in sent:
            return
        sent[stage] = True
        buttons = [0.0] * 7 + [0.8] + [0.0] * 9
        if stage == 1:
            pad = dict(index=0, button_values=buttons, axes=[0.575, 0.0, 0.0, 0.0])
            send(ws, type="gamepad", name="", gamepad=pad)
        elif stage == 3:
            pad = dict(index=0, button_values=buttons, axes=[math.nan, 0.0, 0.0, 0.0])
            send(ws, type="gamepad", name="", gamepad=pad)
        elif stage == 4:
            send(ws, type="gamepad", name="", gamepad={})  # disconnected
        elif stage == 6:
            send(ws, type="button", name=END_BUTTON)

    lines = []
    try:
        take = run_take(scenario, seed=1, visualization=visualization, duration=5.0, realtime=False,
                        on_step=script, progress=lines.append, scene=False)  # fmt: skip
    finally:
        ws.close()
    log, demo = take.inputs, take.demonstration
    assert log.end_reason == "button" and log.end_time < 1.5
    text = " | ".join(lines)
    assert "connected" in text and "NaN" in text and "disconnected" in text
    # The target moved 0.05 m/s in x for each sample that saw the deflected stick.
    axis = log.rows[:, COLUMNS.index("axis_0")]
    deflected = int(np.sum(axis == 0.575))
    assert deflected > 0
    assert demo.p_MS[-1, 0] - take.master.p_MS_initial[0] == pytest.approx(
        deflected * 0.01 * 0.05, abs=3e-4
    )
    assert np.max(demo.muscle_activation) == pytest.approx(0.8)
    assert np.all(np.isfinite(demo.p_WE))


def test_closed_page_ends_the_take_and_keeps_it(scenario, meshcat, visualization):
    ws = websocket.create_connection(meshcat.ws_url(), timeout=5)

    def script(t):
        if t >= 0.25 and ws.connected:
            ws.close()

    take = run_take(scenario, seed=1, visualization=visualization, duration=10.0, realtime=False,
                    on_step=script, progress=lambda line: None)  # fmt: skip
    assert take.inputs.end_reason == "page closed"
    assert 2.0 <= take.inputs.end_time < 2.6
