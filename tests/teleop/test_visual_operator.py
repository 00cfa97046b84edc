"""The operator who acts on what it sees (operator.visual), through Drake: it moves on only
when it sees a waypoint reached, gives up after its patience, corrects the seen error after
its reaction time plus the video delay, and trembles at the drawn frequency."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from hemg_drake.diagrams.demonstration import build_demonstration_diagram
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.tasks.plan import TaskPlan
from hemg_drake.teleop.config import OperatorConfig, VisualConfig
from hemg_drake.teleop.mapping import WorkspaceMapping
from hemg_drake.teleop.operator import SimulatedOperator, set_operator_seed
from hemg_drake.teleop.visual import C, GAVE_UP, S, initial_state, loop_samples, visual_step

MAPPING = WorkspaceMapping(scale=3.0, p_WMo=[0.7, -0.2, 0.25])
PLAN = TaskPlan(
    times=[0.0, 0.6, 1.4, 2.0],
    points=[[0.7, -0.2, 0.25], [0.75, -0.3, 0.25], [0.75, -0.3, 0.2], [0.7, -0.2, 0.25]],
    kinds=["free", "forceful", "free"],
)
STILL = TaskPlan(times=[0.0, 5.0], points=[[0.7, -0.2, 0.25]] * 2, kinds=["free"])
DT = OperatorConfig().period  # 5 ms, the visual law's period


def operator(plan, video_delay=0.0, sheet_normal_W=None, **visual):
    config = OperatorConfig(
        timing_std=0.0, path_std=[0.0, 0.0, 0.0], effort_std=0.0,
        visual=VisualConfig(enabled=True, **visual),
    )  # fmt: skip
    return SimulatedOperator(
        plan=plan, mapping=MAPPING, config=config, video_delay=video_delay,
        sheet_normal_W=sheet_normal_W,
    )  # fmt: skip


def start(system, seen, p_MS=None, seed=None):
    """A simulator with the tool seen at ``seen`` (W) and the stylus held at ``p_MS`` (M);
    ``seed``: the operator's draws of PLAN (set_operator_seed)."""
    simulator = Simulator(system)
    context = simulator.get_mutable_context()
    if seed is not None:
        set_operator_seed(system, context, PLAN, seed)  # a clone is a plain Diagram
    p_MS = MAPPING.slave_to_master(PLAN.points[0]) if p_MS is None else p_MS
    for name, value in (("p_MS", p_MS), ("v_MS", np.zeros(3)), ("feedback_force", np.zeros(3)),
                        ("p_WE_seen", np.asarray(seen, float))):  # fmt: skip
        system.GetInputPort(name).FixValue(context, value)
    simulator.Initialize()
    return simulator, context


def test_moves_on_when_it_sees_the_waypoint_then_gives_up_after_its_patience():
    # The tool is seen at the first waypoint all along: the clock reaches 0.6 s, waits the
    # 0.2 s dwell there (it counts from the period that arrives), passes, and stops at the
    # second waypoint (1.4 s), never seen; 0.5 s later the operator lets go.
    system = operator(PLAN, patience=0.5)
    simulator, context = start(system, PLAN.points[1])
    simulator.AdvanceTo(1.0)
    state = system.visual_state(context)
    assert state[S] == pytest.approx(1.0 - 0.2, abs=1.5 * DT)
    simulator.AdvanceTo(1.4 + 0.2 + 0.49)
    state = system.visual_state(context)
    assert state[S] == pytest.approx(1.4) and not state[GAVE_UP]
    assert np.linalg.norm(system.GetOutputPort("hand_force").Eval(context)) > 1.0
    simulator.AdvanceTo(1.4 + 0.2 + 0.52)
    assert system.visual_state(context)[GAVE_UP] == 1.0
    np.testing.assert_array_equal(system.GetOutputPort("hand_force").Eval(context), np.zeros(3))
    simulator.AdvanceTo(2.5)  # ten muscle time constants later: at rest
    assert system.GetOutputPort("activation").Eval(context)[0] == pytest.approx(0.05, abs=1e-4)


@pytest.mark.parametrize("efference_copy", [False, True])
def test_corrects_the_seen_error_after_reaction_and_video_delay(efference_copy):
    # A still plan; the tool is seen where it should be until t1 = 0.5 s, then 2 cm off in
    # W (2/3 cm in M, scale 3). The operator sees the change 0.1 s (video) + 0.2 s
    # (reaction) later, then integrates w_c (e - tol e/|e|) each 5 ms: the hand, holding
    # the stylus on the plan, pulls with 300 N/m times that correction. With an efference
    # copy the corrections sent since count as under way (none is seen yet: the loop's
    # latency is 0.3 s), so the correction c approaches the error's excess instead of
    # growing with it: c_n = (|e| - tol)(1 - (1 - w_c dt)^n), forward Euler of
    # c' = w_c (|e| - tol - c).
    system = operator(
        STILL, video_delay=0.1, gain=4.0, tolerance=0.003, efference_copy=efference_copy
    )
    p0 = STILL.points[0]
    simulator, context = start(system, p0)
    simulator.AdvanceTo(0.5)
    offset = np.array([0.0, 0.02, 0.0])
    system.GetInputPort("p_WE_seen").FixValue(context, p0 + offset)
    simulator.AdvanceTo(0.5 + 0.29)
    np.testing.assert_allclose(system.GetOutputPort("hand_force").Eval(context), 0, atol=1e-12)
    simulator.AdvanceTo(0.5 + 0.3 + 0.2)
    error = -(MAPPING.slave_to_master(p0 + offset) - MAPPING.slave_to_master(p0))
    rate = 4.0 * error * (1 - 0.003 / np.linalg.norm(error))  # m/s
    force = system.GetOutputPort("hand_force").Eval(context)
    # 0.2 s of integration, within one period either side.
    if efference_copy:
        excess = np.linalg.norm(error) - 0.003
        low, high = (300 * excess * (1 - (1 - 4.0 * DT) ** n) for n in (39, 41))
        assert low <= np.linalg.norm(force) <= high
    else:
        expected = 300 * 0.2 * np.linalg.norm(rate)
        assert np.linalg.norm(force) == pytest.approx(expected, rel=DT / 0.2 + 1e-9)
    direction = rate / np.linalg.norm(rate)
    np.testing.assert_allclose(force / np.linalg.norm(force), direction, atol=1e-9)


def test_an_efference_copy_does_not_correct_a_move_seen_late():
    # One 15 cm move in 1 s (5 cm/s in M), the slave seen exactly on the plan as it goes.
    # Seen 0.1 s (video) + 0.2 s (reaction) late, the tool lags the plan by 1.5 cm in M,
    # far beyond the 3 mm tolerance: compared with the plan now, that lag is integrated as
    # error, into the correction; compared with the plan when the image was taken (the
    # efference copy), what is left is at most a sample's motion (0.25 mm), under the
    # tolerance: no correction.
    move = TaskPlan(
        times=[0.0, 1.0], points=[[0.7, -0.2, 0.25], [0.7, -0.05, 0.25]], kinds=["free"]
    )
    corrections = []
    for efference_copy in (True, False):
        system = operator(move, video_delay=0.1, efference_copy=efference_copy)
        simulator, context = start(system, move.points[0])
        seen = system.GetInputPort("p_WE_seen")
        for k in range(1, 181):  # to 0.9 s, the tool where the plan is at each sample
            seen.FixValue(context, move.position_velocity_floats(context.get_time())[0])
            simulator.AdvanceTo(k * DT)
        corrections.append(np.linalg.norm(system.visual_state(context)[C]))
    assert corrections[0] == 0.0
    # Without it: from 0.3 s on, 4 rad/s times (1.5 cm - 3 mm) each second, ~0.7 cm by 0.9 s.
    assert corrections[1] == pytest.approx(4.0 * (0.015 - 0.003) * 0.6, rel=0.05)


def test_sees_pen_down_segments_on_the_sheet_not_in_depth():
    # Paper at z = 0.25 m; the plan goes down from 5 mm above it to 15 mm under it (5 mm in
    # M, beyond the 3 mm tolerance), draws a 5 cm chord there, then lifts. The pen is seen on the paper above the
    # press point all along. Given the sheet's normal, the waypoint between the two pen-down
    # segments counts as reached (the depth is felt, not seen) and the operator moves on to
    # the chord's end (never seen reached: it holds there); its correction has no component
    # along the normal. Without the normal it holds at the press point, correcting downward.
    paper = 0.25
    plan = TaskPlan(
        times=[0.0, 0.5, 1.0, 2.0],
        points=[[0.75, -0.3, paper + 0.005], [0.75, -0.3, paper - 0.015],
                [0.8, -0.3, paper - 0.015], [0.75, -0.3, paper + 0.005]],
        kinds=["forceful", "forceful", "free"], pen_down=[True, True, False],
    )  # fmt: skip
    seen = [0.75, -0.3, paper]
    n_M = MAPPING.R_WM.inverse().multiply([0.0, 0.0, 1.0])
    clocks, corrections = [], []
    for normal in ([0.0, 0.0, 2.0], None):  # any length: the system normalises it
        system = operator(plan, sheet_normal_W=normal)
        simulator, context = start(system, seen, p_MS=MAPPING.slave_to_master(plan.points[0]))
        simulator.AdvanceTo(1.5)
        state = system.visual_state(context)
        clocks.append(state[S])
        corrections.append(state[C])
    assert clocks[0] == pytest.approx(1.0) and clocks[1] == pytest.approx(0.5)
    assert abs(corrections[0] @ n_M) < 1e-12 and np.linalg.norm(corrections[0]) > 1e-3
    # Without the normal: the depth error seen, corrected downward (into the paper).
    assert corrections[1] @ n_M < -1e-3


def test_tremor_is_the_drawn_sinusoid():
    # Draws [0.5, 0, 0.25, 0.5]: f = 8 + 4 x 0.5 = 10 Hz, phases 0, 1/4, 1/2 of a cycle; at
    # t = 12.5 ms (an eighth of a cycle) the target is A [sin 45, sin 135, sin 225] deg off
    # the plan, and the hand holding the stylus on the plan pulls 300 N/m times that.
    system = operator(STILL, tremor_amplitude=0.001)
    simulator = Simulator(system)
    context = simulator.get_mutable_context()
    source = system.GetSubsystemByName("visual")
    system.GetMutableSubsystemContext(source, context).SetDiscreteState([0.5, 0.0, 0.25, 0.5])
    p_plan = MAPPING.slave_to_master(STILL.points[0])
    for name, value in (("p_MS", p_plan), ("v_MS", np.zeros(3)), ("feedback_force", np.zeros(3)),
                        ("p_WE_seen", STILL.points[0])):  # fmt: skip
        system.GetInputPort(name).FixValue(context, value)
    simulator.Initialize()
    simulator.AdvanceTo(0.0125)
    root_half = np.sqrt(0.5)
    np.testing.assert_allclose(
        system.GetOutputPort("hand_force").Eval(context),
        300 * 0.001 * np.array([root_half, root_half, -root_half]), atol=1e-9,
    )


@pytest.mark.parametrize("efference_copy", [False, True])
def test_visual_operator_clones(efference_copy):
    system = operator(PLAN, tremor_amplitude=0.001, efference_copy=efference_copy)
    forces = []
    for copy in (system, system.Clone()):
        simulator, context = start(copy, PLAN.points[0], seed=5)
        simulator.AdvanceTo(0.3)
        forces.append(copy.GetOutputPort("hand_force").Eval(context).copy())
    assert np.linalg.norm(forces[0]) > 0.1
    np.testing.assert_array_equal(forces[0], forces[1])


@pytest.mark.parametrize("task", ["drawing", "cotter_pin"])
def test_the_demonstration_gives_the_operator_the_sheets_normal(task):
    # The sheet's normal in M, from the scenario's own sheet pose (turned 30 deg) and
    # mapping: R_WM^T z_W for the drawing; none for the pin.
    scenario = load_scenario(shipped_scenario(task), overrides=[
        "operator.visual.enabled=true", "scene.yaw_deg=30",
    ])  # fmt: skip
    diagram = build_demonstration_diagram(scenario).diagram
    normal = diagram.GetSubsystemByName("operator").sheet_normal_M()
    if task == "cotter_pin":
        assert normal is None
        return
    R_WM = scenario.workspace_mapping().R_WM.matrix()
    np.testing.assert_allclose(normal, R_WM.T @ [0.0, 0.0, 1.0], atol=1e-12)


@pytest.mark.parametrize("normal, message", [
    ([0.0, 0.0, 0.0], "sheet_normal_W must not be zero"),
    ([0.0, 1.0], "sheet_normal_W"),
    ([0.0, float("nan"), 1.0], "sheet_normal_W"),
])  # fmt: skip
def test_a_malformed_sheet_normal_is_refused(normal, message):
    with pytest.raises(ValueError, match=message):
        operator(PLAN, sheet_normal_W=normal)


@pytest.mark.parametrize("efference_copy", [True, False])
def test_under_delay_the_efference_copy_settles_where_the_integral_oscillates(efference_copy):
    # The loop closed by hand around the law: a still plan, the slave missing every command
    # by m = 1 cm (in M) and seen L = 0.7 s after it was sent (0.25 s each way and 0.2 s of
    # reaction). The seen error's plain integral is a delayed integrator,
    # w_c L = 2.8 > pi/2: it oscillates (bounded by the 3 cm limit). With the efference
    # copy the loop is c' = w_c (m - tol - c): it settles at 7 mm, the miss seen within the
    # tolerance, monotonically.
    config = VisualConfig(enabled=True, efference_copy=efference_copy)
    plan_M = STILL.in_frame(MAPPING.slave_to_master(STILL.points))
    p_plan = np.asarray(plan_M.points[0])
    miss = np.array([0.01, 0.0, 0.0])
    n = loop_samples(config, 0.25, 0.25, DT)
    assert n == 140
    state, sent = initial_state(), [np.zeros(4)] * n
    history = []
    for _ in range(1000):  # 5 s
        seen = p_plan + sent[0][1:4] - miss  # the command sent L ago, missed by m
        new = visual_step(state, seen, plan_M, config, DT, sent=sent[0])
        sent = [*sent[1:], state[:4].copy()]
        state = new
        history.append(state[C][0])
    history = np.array(history)
    if efference_copy:
        assert np.all(np.diff(history) >= 0)
        assert history[-1] == pytest.approx(0.01 - 0.003, abs=1e-6)
    else:  # swinging beyond the miss and back, the whole 3 cm bound
        assert history.max() == pytest.approx(0.03) and history.min() < -0.01
