"""TaskPlan: minimum-jerk interpolation, YAML-friendly loading, errors, seeded variability."""

import textwrap

import numpy as np
import pytest
from pydrake.common.yaml import yaml_load_data

from hemg_drake.tasks.plan import TaskPlan

PLAN_YAML = textwrap.dedent(
    """
    times: [0.0, 1.0, 2.5, 3.0]
    points: [[0.6, -0.2, 0.3], [0.7, -0.2, 0.3], [0.7, 0.0, 0.2], [0.6, 0.0, 0.2]]
    kinds: [free, forceful, free]
    pen_down: [false, true, false]
    """
)


@pytest.fixture
def plan():
    # Parsed by Drake's YAML reader, as a scenario file would be.
    return TaskPlan.from_dict(yaml_load_data(PLAN_YAML))


def test_passes_through_waypoints_with_zero_velocity(plan):
    np.testing.assert_allclose(plan.position(plan.times), plan.points, atol=1e-15)
    np.testing.assert_allclose(plan.velocity(plan.times), np.zeros((4, 3)), atol=1e-15)
    # Minimum jerk: halfway in time is halfway in space, at 1.875 x the mean speed.
    np.testing.assert_allclose(plan.position(0.5), [0.65, -0.2, 0.3])
    np.testing.assert_allclose(plan.velocity(0.5), [1.875 * 0.1, 0.0, 0.0])


def test_velocity_is_the_derivative_of_position(plan):
    t = np.linspace(-0.5, 3.5, 801)
    h = 1e-6
    numeric = (plan.position(t + h) - plan.position(t - h)) / (2 * h)
    np.testing.assert_allclose(plan.velocity(t), numeric, atol=1e-6)
    # Continuous across waypoints: no jump from one side to the other.
    for t_k in plan.times[1:-1]:
        np.testing.assert_allclose(plan.velocity(t_k - 1e-9), plan.velocity(t_k + 1e-9), atol=1e-6)


def test_float_path_equals_the_array_methods_to_the_bit(plan):
    for t in np.linspace(plan.start_time - 0.5, plan.end_time + 0.5, 97).tolist():
        position, velocity = plan.position_velocity_floats(t)
        assert position == plan.position(t).tolist()
        assert velocity == plan.velocity(t).tolist()


def test_plan_mapped_by_its_waypoints_is_the_mapped_plan(plan):
    R = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    offset, scale = np.array([0.6, -0.8, 0.2]), 2.0
    mapped = plan.in_frame((plan.points - offset) @ R / scale)
    t = np.linspace(plan.start_time, plan.end_time, 50)
    np.testing.assert_allclose(mapped.position(t), (plan.position(t) - offset) @ R / scale, atol=1e-15)
    np.testing.assert_allclose(mapped.velocity(t), plan.velocity(t) @ R / scale, atol=1e-15)
    assert mapped.kinds == plan.kinds and np.array_equal(mapped.times, plan.times)


def test_holds_end_points_outside_the_plan(plan):
    np.testing.assert_array_equal(plan.position(-1.0), plan.points[0])
    np.testing.assert_array_equal(plan.position(10.0), plan.points[-1])
    np.testing.assert_array_equal(plan.velocity(10.0), np.zeros(3))
    assert plan.position(np.zeros((2, 5))).shape == (2, 5, 3)


def test_segments_carry_kind_and_pen(plan):
    assert [plan.segment(t).kind for t in (0.5, 1.0, 2.0, 2.9)] == [
        "free",
        "forceful",
        "forceful",
        "free",
    ]
    assert plan.segment(1.7).pen_down and not plan.segment(0.2).pen_down
    assert plan.segment(-3.0).index == 0 and plan.segment(9.0).index == 2
    assert plan.segment(2.0).effort == 1.0


def test_plain_data_round_trip(plan):
    again = TaskPlan.from_dict(plan.to_dict())
    for name in ("times", "points", "effort"):
        np.testing.assert_array_equal(getattr(again, name), getattr(plan, name))
    assert again.kinds == plan.kinds and again.pen_down == plan.pen_down


def arrays(plan):
    return np.concatenate([plan.times, plan.points.ravel(), plan.effort])


def test_perturbed_is_seeded(plan):
    a, b, c = plan.perturbed(7), plan.perturbed(7), plan.perturbed(8)
    np.testing.assert_array_equal(arrays(a), arrays(b))
    assert np.max(np.abs(arrays(a) - arrays(c))) > 1e-4
    assert a.kinds == plan.kinds and a.pen_down == plan.pen_down
    assert a.start_time == plan.start_time and np.all(np.diff(a.times) > 0)
    np.testing.assert_array_equal(
        arrays(plan.perturbed(3, timing_std=0, path_std=0, effort_std=0)), arrays(plan)
    )


def test_perturbed_variability_has_the_requested_size(plan):
    runs = [
        plan.perturbed(seed, timing_std=0.1, path_std=(0.004, 0.002, 0.0), effort_std=0.2)
        for seed in range(300)
    ]
    offsets = np.array([run.points - plan.points for run in runs])  # (runs, waypoints, 3)
    np.testing.assert_allclose(offsets.std(axis=0).mean(axis=0)[:2], [0.004, 0.002], rtol=0.2)
    assert np.all(offsets[..., 2] == 0.0)  # a zero-std axis stays put (pen on the paper)
    # Smooth: waypoints a third of the plan apart move together, with the correlation
    # (1 + cos(pi/3)/2 + cos(2 pi/3)/2) / 2 = 0.5 of the documented offset law.
    x = offsets[:, :, 0]
    assert np.corrcoef(x[:, 0], x[:, 1])[0, 1] == pytest.approx(0.5, abs=0.12)
    stretch = np.log([np.diff(run.times) / np.diff(plan.times) for run in runs])
    assert stretch.std() == pytest.approx(0.1, rel=0.2)
    effort = np.log([run.effort for run in runs])
    assert effort.std() == pytest.approx(0.2, rel=0.2)


BASE = yaml_load_data(PLAN_YAML)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(times=[0.0, 1.0, 1.0, 3.0]), r"'times' must be strictly increasing: times\[2\]"),
        (dict(times=[0.0]), "'times'"),
        (dict(times=[0.0, 1.0, float("nan"), 3.0]), r"'times' is not finite at index \[2\]"),
        (dict(points=[[0, 0, 0]] * 3 + [[0, 0]]), "'points'"),
        (dict(points=[[0, 0, 0]] * 3), r"'points' must have shape \(4, 3\)"),
        (
            dict(points=[[0, 0, 0]] * 3 + [[0, float("nan"), 0]]),
            r"'points' is not finite at index \[3, 1\]",
        ),
        (dict(kinds=["free", "slow", "free"]), r"'kinds'\[1\] = 'slow'"),
        (dict(kinds=["free", "free"]), "'kinds' must have 3 entries"),
        (dict(pen_down=[1, 0, 0]), "'pen_down'"),
        (dict(effort=[1.0, -1.0, 1.0]), "'effort'"),
        (dict(times=["a", 1, 2, 3]), "'times' must hold numbers"),
        (dict(speed=[1.0]), r"unknown field\(s\) \['speed'\]"),
    ],
)
def test_bad_plans_name_the_field(change, message):
    with pytest.raises(ValueError, match=message):
        TaskPlan.from_dict({**BASE, **change})


def test_missing_field_and_bad_perturbation_are_named(plan):
    with pytest.raises(ValueError, match=r"missing field\(s\) \['kinds'\]"):
        TaskPlan.from_dict({"times": BASE["times"], "points": BASE["points"]})
    with pytest.raises(ValueError, match="timing_std"):
        plan.perturbed(0, timing_std=-0.1)
    with pytest.raises(ValueError, match="effort_std"):
        plan.perturbed(0, effort_std=np.inf)
    with pytest.raises(ValueError, match="path_std"):
        plan.perturbed(0, path_std=[0.1, np.nan, 0.0])
    for seed in (-1, 1.0, True):
        with pytest.raises(ValueError, match="seed must be a non-negative integer"):
            plan.perturbed(seed)
    with pytest.raises(ValueError, match="time"):
        plan.position(np.nan)
