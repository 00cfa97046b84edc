"""The human-like operator style (operator.style: human): its timing against hand values, its
statistics over seeds, and same seed same bytes, in the plan and in the Drake Context."""

import numpy as np
import pytest

from hemg_drake.diagrams.demonstration import operator_plan
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.tasks.plan import TaskPlan
from hemg_drake.teleop.config import HumanStyleConfig
from hemg_drake.teleop.human_style import human_draw_count, human_draws, humanised

STYLE = HumanStyleConfig()
# Hand-written: a 2-segment plan, a 1 m free move up then a 0.5 s forceful hold.
PLAN = TaskPlan(times=[0.0, 1.0, 1.5], points=[[0, 0, 0], [0, 0, 1.0], [0, 0, 1.0]],
                kinds=("free", "forceful"))  # fmt: skip


def draws(idle=0.5, take=0.5, phases=((0.5, 0.9, 0.5, 0.9, 0.5), (0.5, 0.9, 0.5, 0.9, 0.5))):
    """[idle, take tempo, per segment (tempo, pause?, pause length, overshoot?, size)]."""
    return np.array([idle, take, *np.ravel(phases)])


def test_the_draw_layout_is_two_per_take_and_five_per_segment():
    assert human_draw_count(PLAN) == 2 + 5 * 2


def test_middle_draws_only_shift_by_the_middle_idle():
    plan = humanised(PLAN, draws(), STYLE)
    # idle 0.3 + 0.5 (2.0 - 0.3) = 1.15 s; tempo sqrt(0.5 * 2) = 1; no pause, no overshoot.
    np.testing.assert_allclose(plan.times, [1.15, 2.15, 2.65])
    np.testing.assert_array_equal(plan.points, PLAN.points)


@pytest.mark.parametrize("take, phase, scale", [
    (0.0, 0.5, 2.0),   # the slowest take: every duration doubled
    (1.0, 0.5, 0.5),   # the fastest: halved
    (0.0, 0.0, 2.0),   # slower still in the phase: clipped at 0.5x speed
    (0.5, 1.0, 1 / 1.5),  # a middle take, the phase 1.5x faster
])  # fmt: skip
def test_tempo_scales_each_duration_within_half_to_twice(take, phase, scale):
    row = (phase, 0.9, 0.5, 0.9, 0.5)
    plan = humanised(PLAN, draws(idle=0.0, take=take, phases=(row, row)), STYLE)
    np.testing.assert_allclose(np.diff(plan.times), np.array([1.0, 0.5]) * scale)
    assert plan.start_time == pytest.approx(0.3)


def test_a_pause_holds_the_waypoint_in_the_ending_segment_s_kind():
    phases = ((0.5, 0.0, 0.25, 0.9, 0.5), (0.5, 0.0, 0.5, 0.9, 0.5))
    plan = humanised(PLAN, draws(idle=0.0, phases=phases), STYLE)
    # A pause after segment 0 only (none after the last): 0.2 + 0.25 (1.0 - 0.2) = 0.4 s.
    np.testing.assert_allclose(plan.times, [0.3, 1.3, 1.7, 2.2])
    np.testing.assert_array_equal(plan.points[1], plan.points[2])
    assert plan.kinds == ("free", "free", "forceful")


def test_a_free_move_overshoots_at_most_1_cm_then_corrects():
    phases = ((0.5, 0.9, 0.5, 0.0, 1.0), (0.5, 0.9, 0.5, 0.0, 1.0))
    plan = humanised(PLAN, draws(idle=0.0, phases=phases), STYLE)
    # 30 % of the 1 m move capped at 0.01 m, then back in 0.3 s; the forceful hold does not.
    np.testing.assert_allclose(plan.points[:, 2], [0.0, 1.01, 1.0, 1.0])
    np.testing.assert_allclose(plan.times, [0.3, 1.3, 1.6, 2.1])


def test_over_seeds_takes_differ_2x_or_more_in_length_and_start_late():
    scenario = load_scenario(shipped_scenario("cotter_pin"), overrides=["operator.style=human"])
    plans = [operator_plan(scenario, seed) for seed in range(5001, 5041)]
    starts = np.array([p.start_time for p in plans])
    lengths = np.array([p.end_time - p.start_time for p in plans])
    assert starts.min() >= 0.3 and starts.max() <= 2.0 and np.ptp(starts) > 1.0
    assert lengths.max() / lengths.min() >= 2.0
    # Nominal 3.5 s at 0.5-2x speed, plus at most 3 pauses of 1 s and one 0.3 s correction.
    assert 3.5 / 2 <= lengths.min() and lengths.max() <= 3.5 * 2 + 3 * 1.0 + 0.3
    segments = [len(p.kinds) for p in plans]
    assert min(segments) == 4 and max(segments) > 5  # some pause, some correct


def test_same_seed_same_bytes_other_seeds_differ_and_scripted_is_untouched():
    human = load_scenario(shipped_scenario("cotter_pin"), overrides=["operator.style=human"])
    scripted = load_scenario(shipped_scenario("cotter_pin"))
    one, again, other = (operator_plan(human, s).to_dict() for s in (5001, 5001, 5002))
    assert one == again and one != other
    nominal = scripted.task_plan()
    assert operator_plan(scripted, 5001).to_dict() == nominal.perturbed(5001).to_dict()
    np.testing.assert_array_equal(human_draws(nominal, 7), human_draws(nominal, 7))


def test_the_operator_s_context_follows_the_seeded_human_plan():
    from hemg_drake.teleop.mapping import WorkspaceMapping
    from hemg_drake.teleop.operator import SimulatedOperator
    from pydrake.systems.analysis import Simulator

    scenario = load_scenario(shipped_scenario("cotter_pin"), overrides=["operator.style=human"])
    operator = SimulatedOperator(plan=scenario.task_plan(), mapping=WorkspaceMapping(),
                                 config=scenario.operator)  # fmt: skip
    assert operator.HasSubsystemNamed("human")
    context = operator.CreateDefaultContext()
    for name in ("p_MS", "v_MS", "feedback_force"):
        operator.GetInputPort(name).FixValue(context, np.zeros(3))
    operator.set_seed(context, 5003)
    Simulator(operator, context).Initialize()
    assert operator.plan(context).to_dict() == operator_plan(scenario, 5003).to_dict()
    plain = SimulatedOperator(plan=scenario.task_plan(), mapping=WorkspaceMapping())
    assert not plain.HasSubsystemNamed("human")


def test_a_range_upside_down_is_refused_naming_its_key():
    with pytest.raises(ValueError, match="operator.human.tempo_range"):
        load_scenario(shipped_scenario("cotter_pin"),
                      overrides=["operator.human.tempo_range=[2.0,0.5]"])  # fmt: skip
