"""CLIK (eq. 21) on the Baxter arm, driven through Drake."""

import dataclasses as dc

import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from hemg_drake.control.clik import Clik
from hemg_drake.control.config import ClikConfig
from hemg_drake.robots.baxter import add_baxter_arm

# The test's own plant of the arm (not the CLIK's): forward kinematics and Jacobians.
_PLANT = MultibodyPlant(0.0)
_ARM = add_baxter_arm(_PLANT)
_PLANT.Finalize()
_CONTEXT = _PLANT.CreateDefaultContext()


def p_WE(q):
    """The tool point at arm configuration q (m), on the test's plant."""
    _PLANT.SetPositions(_CONTEXT, _ARM.model_instance, q)
    return _ARM.tool_frame.CalcPoseInWorld(_CONTEXT).translation().copy()


def make_clik(p_EoE_E=None, **changes):
    """A kinematic-only diagram: the CLIK (its own plant, in a scene) reads a fixed arm
    state and a fixed target; ``changes`` replace ClikConfig fields."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    arm = add_baxter_arm(plant)
    plant.Finalize()
    clik = builder.AddSystem(
        Clik(
            plant=plant, model_instance=arm.model_instance, frame_E=arm.tool_frame,
            config=dc.replace(ClikConfig(), **changes), p_EoE_E=p_EoE_E,
        )  # fmt: skip
    )
    builder.ExportInput(clik.GetInputPort("p_WE_desired"), "p_WE_desired")
    builder.ExportInput(clik.GetInputPort("state"), "state")
    builder.ExportOutput(clik.GetOutputPort("q_desired"), "q_desired")
    builder.ExportOutput(clik.GetOutputPort("v_desired"), "v_desired")
    diagram = builder.Build()
    return diagram, clik, _ARM  # the test plant's handles (the same joints and limits)


def finite_difference_jacobian(q, h=1e-6):
    """d p_WE / d q (3, 7) by central differences of the forward kinematics."""
    return np.column_stack(
        [(p_WE(q + h * np.eye(7)[j]) - p_WE(q - h * np.eye(7)[j])) / (2 * h) for j in range(7)]
    )


def run_clik(target, q0, seconds, **kwargs):
    diagram, clik, arm = make_clik(**kwargs)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    diagram.GetInputPort("p_WE_desired").FixValue(context, target)
    diagram.GetInputPort("state").FixValue(context, np.concatenate([q0, np.zeros(7)]))
    simulator.Initialize()
    simulator.AdvanceTo(seconds)
    q_d = diagram.GetOutputPort("q_desired").Eval(context)
    v_d = diagram.GetOutputPort("v_desired").Eval(context)
    return q_d, v_d, clik, arm


@pytest.mark.parametrize("method, gain", [("transpose", 300.0), ("dls", 50.0)])
def test_converges_to_reachable_target(method, gain):
    q_goal = np.array([0.3, -0.3, 0.2, 1.0, -0.2, 0.8, 0.1])
    q0 = np.array([0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0])
    _, clik, _ = make_clik()
    target = p_WE(q_goal)
    assert np.linalg.norm(target - p_WE(q0)) > 0.1  # a real move
    q_d, v_d, clik, _ = run_clik(target, q0, 3.0, method=method, gain=gain)
    assert np.linalg.norm(p_WE(q_d) - target) < 1e-3
    assert np.linalg.norm(v_d) < 0.05  # settled


def test_starts_from_the_measured_state():
    q0 = np.array([0.1, -0.4, 0.1, 0.9, 0.1, 1.0, 0.2])
    _, clik, _ = make_clik()
    q_d, v_d, _, _ = run_clik(p_WE(q0), q0, 0.0)
    np.testing.assert_allclose(q_d, q0)
    np.testing.assert_allclose(v_d, 0.0)


@pytest.mark.parametrize("method", ["transpose", "dls"])
def test_unreachable_target_stays_finite_within_limits(method):
    q0 = np.array([0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0])
    q_d, v_d, clik, arm = run_clik(np.array([3.0, -2.0, 2.5]), q0, 2.0, method=method)
    assert np.all(np.isfinite(q_d)) and np.all(np.isfinite(v_d))
    assert np.all(q_d >= arm.position_lower) and np.all(q_d <= arm.position_upper)
    assert np.all(np.abs(v_d) <= arm.velocity_limit + 1e-9)
    # Stretched toward the target: closer than at the start.
    target = np.array([3.0, -2.0, 2.5])
    assert np.linalg.norm(p_WE(q_d) - target) < np.linalg.norm(p_WE(q0) - target)


@pytest.mark.parametrize("method", ["transpose", "dls"])
def test_step_is_eq_21_with_a_finite_difference_jacobian(method):
    """Two updates equal q + dt * K * J^T e (transpose) or q + dt * K * J^T (J J^T +
    lambda^2 I)^-1 e (dls), with J by finite differences of the forward kinematics."""
    q0 = np.array([0.2, -0.5, 0.1, 0.8, 0.0, 1.0, 0.0])
    _, clik, _ = make_clik()
    # 2 cm away: small enough that no velocity limit scales the step.
    target = p_WE(q0) + np.array([0.02, -0.01, 0.01])
    # Updates fire at t = 0 and t = 1 ms before 1.5 ms.
    gain, damping = (20.0, 0.05) if method == "transpose" else (2.0, 0.3)
    q_d, v_d, clik, arm = run_clik(
        target, q0, 1.5e-3, gain=gain, method=method, damping=damping
    )
    assert np.all(np.abs(v_d) < 0.5 * arm.velocity_limit)

    def step(q):
        J = finite_difference_jacobian(q)
        e = target - p_WE(q)
        if method == "dls":
            e = np.linalg.solve(J @ J.T + damping**2 * np.eye(3), e)
        return q + 1e-3 * gain * J.T @ e

    q1 = step(q0)
    q2 = step(q1)
    np.testing.assert_allclose(q_d, q2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v_d, (q2 - q1) / 1e-3, rtol=0, atol=1e-9)
    assert np.linalg.norm(q2 - q0) > 1e-4  # a real step


@pytest.mark.parametrize(
    "kwargs", [{}, {"method": "dls", "gain": 50.0}, {"orientation_gain": 10.0}]
)
def test_nan_target_holds_the_reference(kwargs):
    q0 = np.array([0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0])
    q_d, v_d, _, _ = run_clik(np.array([np.nan, 0.0, 0.0]), q0, 0.05, **kwargs)
    np.testing.assert_allclose(q_d, q0)
    np.testing.assert_allclose(v_d, 0.0)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"method": "pinv"}, "method"),
        ({"gain": -1.0}, "gain"),
        ({"period": 0.0}, "period"),
        ({"damping": float("nan")}, "damping"),
        ({"p_EoE_E": [0.0, 0.0]}, "p_EoE_E"),
        ({"p_EoE_E": [0.0, np.nan, 0.0]}, "p_EoE_E must be finite"),
        ({"method": "dls", "damping": -0.1}, "damping"),
        ({"limit_margin": float("nan")}, "limit_margin"),
        ({"limit_margin": -0.1}, "limit_margin"),
    ],
)
def test_bad_parameters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        make_clik(**kwargs)


def test_velocity_columns_index_like_the_plant():
    """Indexing with velocity_columns picks what GetVelocitiesFromArray picks, by a slice."""
    from pydrake.multibody.plant import MultibodyPlant
    from pydrake.multibody.tree import SpatialInertia

    from hemg_drake.control.clik import velocity_columns

    plant = MultibodyPlant(1e-3)
    other = plant.AddModelInstance("other")
    plant.AddRigidBody("free", other, SpatialInertia.SolidSphereWithMass(1.0, 0.1))
    arm = add_baxter_arm(plant)
    plant.Finalize()
    values = np.arange(plant.num_velocities(), dtype=float) * 10.0
    for model in (arm.model_instance, other):
        columns = velocity_columns(plant, model)
        np.testing.assert_array_equal(values[columns], plant.GetVelocitiesFromArray(model, values))
        assert isinstance(columns, slice)  # Drake numbers a model's velocities contiguously


def _jacobian(plant, arm, q):
    """The arm's (3, 7) translational Jacobian of the tool point, on a context of the test's."""
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, arm.model_instance, q)
    W = plant.world_frame()
    return plant.CalcJacobianTranslationalVelocity(
        context, JacobianWrtVariable.kV, arm.tool_frame, np.zeros(3), W, W
    )


def test_a_joint_at_its_limit_stops_alone():
    """Issue 13: joint e0 at its lower limit, pushed further down, stops; the others keep
    the unclipped law's rates gain * J^T e (all within their velocity limits)."""
    margin, gain, pinned = 0.02, 300.0, 2
    _, clik, arm = make_clik()
    q0 = np.array([0.2, -0.5, 0.0, 0.8, 0.0, 1.0, 0.0])
    q0[pinned] = arm.position_lower[pinned] + margin  # exactly at the CLIK's limit
    J = _jacobian(_PLANT, _ARM, q0)
    # A target error along -J's column of the pinned joint pushes it outward, and is sized so
    # that the fastest other joint runs at 80 % of its velocity limit.
    direction = -J[:, pinned] / np.linalg.norm(J[:, pinned])
    others = np.arange(7) != pinned
    unit_rates = gain * J.T @ direction
    e = direction * 0.8 / np.max(np.abs(unit_rates[others]) / arm.velocity_limit[others])
    law = gain * J.T @ e
    # The premise: the pinned joint alone would exceed its velocity limit by over 2x.
    assert law[pinned] < -2.0 * arm.velocity_limit[pinned]
    target = p_WE(q0) + e

    q_d, v_d, _, _ = run_clik(target, q0, 0.5e-3, gain=gain, limit_margin=margin)
    assert v_d[pinned] == 0.0 and q_d[pinned] == q0[pinned]
    np.testing.assert_allclose(v_d[others], law[others], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(q_d, q0 + 1e-3 * v_d, rtol=0, atol=1e-15)

    # Held for a while: the pinned joint stays put, every rate and position within limits.
    q_d, v_d, _, _ = run_clik(target, q0, 0.3, gain=gain, limit_margin=margin)
    assert q_d[pinned] == q0[pinned]
    assert np.all(np.abs(v_d) <= arm.velocity_limit)
    assert np.all(q_d >= arm.position_lower + margin) and np.all(q_d <= arm.position_upper - margin)


def _reference_limited_rates(q, qdot, v_max, lower, upper, period):
    """The limits' rule as stated, one joint at a time (independent of the kernel)."""
    rates = []
    for j in range(len(q)):
        rate = float(qdot[j])
        if (q[j] >= upper[j] and rate > 0.0) or (q[j] <= lower[j] and rate < 0.0):
            rate = 0.0  # at its limit and pushed outward: this joint stops
        elif q[j] + period * rate > upper[j]:
            rate = (upper[j] - q[j]) / period  # up to the limit, no further
        elif q[j] + period * rate < lower[j]:
            rate = (lower[j] - q[j]) / period
        rates.append(rate)
    worst = max(abs(rate) / v for rate, v in zip(rates, v_max))
    if worst > 1.0:
        rates = [rate / worst for rate in rates]
    return np.array(rates)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_limits_against_the_rule_in_a_simulator(seed):
    """Random references near the limits and random targets, one CLIK update each: the rates
    follow the rule (per-joint reference), and the invariants hold."""
    rng = np.random.default_rng(seed)
    margin, gain, period = 0.02, 300.0, 1e-3
    diagram, clik, arm = make_clik(gain=gain, limit_margin=margin)
    lower, upper = arm.position_lower + margin, arm.position_upper - margin
    v_max = arm.velocity_limit
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    pinned_seen = scaled_seen = 0
    for _ in range(20):
        q0 = rng.uniform(lower, upper)
        at_limit = rng.random(7) < 0.3
        q0[at_limit] = np.where(rng.random(7) < 0.5, lower, upper)[at_limit]
        target = p_WE(q0) + rng.normal(0.0, 0.03, 3)
        context.SetTime(0.0)
        diagram.GetInputPort("p_WE_desired").FixValue(context, target)
        diagram.GetInputPort("state").FixValue(context, np.concatenate([q0, np.zeros(7)]))
        simulator.Initialize()  # the initialisation event reads the state; one update at t=0
        simulator.AdvanceTo(0.5 * period)
        q_d = diagram.GetOutputPort("q_desired").Eval(context)
        v_d = diagram.GetOutputPort("v_desired").Eval(context)
        J = _jacobian(_PLANT, _ARM, q0)
        law = gain * J.T @ (target - p_WE(q0))
        np.testing.assert_allclose(
            v_d, _reference_limited_rates(q0, law, v_max, lower, upper, period), atol=1e-9
        )
        # Invariants, without the reference.
        outward = ((q0 >= upper) & (law > 0)) | ((q0 <= lower) & (law < 0))
        assert np.all(v_d[outward] == 0.0)
        assert np.all(np.abs(v_d) <= v_max * (1 + 1e-12))
        assert np.all((q_d >= lower) & (q_d <= upper))
        free = ~outward & (q0 + period * law <= upper) & (q0 + period * law >= lower)
        if np.all(np.abs(law[free]) <= v_max[free]) and np.all(free | outward):
            np.testing.assert_allclose(v_d[free], law[free], rtol=1e-9, atol=1e-12)
        pinned_seen += outward.any()
        scaled_seen += np.any(np.abs(law[~outward]) > v_max[~outward])
    assert pinned_seen >= 5 and scaled_seen >= 3


# A configuration that holds the pen 0.6 deg from vertical over a sheet at (0.60, -0.70,
# 0.09) (from solve_tool_point_ik), away from the wrist's singular configurations.
Q_PEN_DOWN = np.array([0.08, -0.83, 0.04, 1.29, -0.03, 1.13, 0.0])


def _tool_axis_and_point(plant, arm, q):
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, arm.model_instance, q)
    X_WE = arm.tool_frame.CalcPoseInWorld(context)
    return X_WE.rotation().matrix()[:, 2], X_WE.translation()


def _tilt(axis_W):
    """Angle (rad) between a tool axis and world -z."""
    return float(np.arccos(np.clip(-axis_W[2], -1.0, 1.0)))


def test_tool_axis_turns_down_at_the_gain_rate_with_the_tool_point_held():
    """Target at the tool point, axis 8 deg off: the angle decays as exp(-k t) (closed form;
    slowed by at most the damping's factor s^2 / (s^2 + mu^2), s >= 0.38 the smaller
    singular value of the axis task here) while the point stays put (the axis task lives in
    the position task's null space)."""
    from hemg_drake.control.clik import AXIS_DAMPING

    k = 5.0
    q0 = Q_PEN_DOWN + np.array([0.0, 0.0, 0.0, 0.0, 0.1, 0.1, 0.0])
    diagram, clik, arm = make_clik(orientation_gain=k)
    plant = _PLANT
    axis0, p0 = _tool_axis_and_point(plant, arm, q0)
    theta0 = _tilt(axis0)
    assert np.degrees(theta0) > 5.0
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    diagram.GetInputPort("p_WE_desired").FixValue(context, p0)
    diagram.GetInputPort("state").FixValue(context, np.concatenate([q0, np.zeros(7)]))
    for t in (0.1, 0.2, 0.4):
        simulator.AdvanceTo(t - 0.5e-3)  # updates at 0, 1, ..., t - 1 ms: t / 1 ms steps
        axis, p = _tool_axis_and_point(plant, arm, diagram.GetOutputPort("q_desired").Eval(context))
        slowest = k * 0.38**2 / (0.38**2 + AXIS_DAMPING**2)
        assert theta0 * np.exp(-k * t) * 0.99 < _tilt(axis) < theta0 * np.exp(-slowest * t) * 1.01
        assert np.linalg.norm(p - p0) < 2e-5


def test_tool_axis_task_leaves_the_tool_point_velocity_of_eq_21():
    """One update from the same reference with the axis task on and off: J v_d is the same
    (null space), the joint rates differ, and the axis turns toward the desired direction."""
    q0 = Q_PEN_DOWN + np.array([0.1, 0.0, -0.2, 0.0, 0.2, 0.2, 0.0])
    _, clik, arm = make_clik()
    target = p_WE(q0) + np.array([0.01, -0.005, 0.004])
    _, v_off, _, _ = run_clik(target, q0, 0.5e-3, gain=20.0)
    _, v_on, _, _ = run_clik(target, q0, 0.5e-3, gain=20.0, orientation_gain=2.0)
    J = _jacobian(_PLANT, _ARM, q0)
    assert np.all(np.abs(v_on) < arm.velocity_limit)  # no limit scales either step
    np.testing.assert_allclose(J @ v_on, J @ v_off, rtol=0, atol=1e-6 * np.linalg.norm(J @ v_off))
    assert np.linalg.norm(v_on - v_off) > 0.1
    axis0, _ = _tool_axis_and_point(_PLANT, _ARM, q0)
    axis1, _ = _tool_axis_and_point(_PLANT, _ARM, q0 + 0.01 * v_on)
    assert _tilt(axis1) < _tilt(axis0)


def test_any_tool_axis_onto_any_direction():
    """The tool's x axis turned onto world +y, from 30+ deg away: aligned within 0.5 deg."""
    q0 = Q_PEN_DOWN
    diagram, clik, arm = make_clik()
    context = _PLANT.CreateDefaultContext()
    _PLANT.SetPositions(context, arm.model_instance, q0)
    x_W = arm.tool_frame.CalcPoseInWorld(context).rotation().matrix()[:, 0]
    desired = np.array([0.0, 1.0, 0.0])
    assert np.degrees(np.arccos(x_W @ desired)) > 30.0
    q_d, _, _, _ = run_clik(
        p_WE(q0), q0, 1.5, axis_E=[1, 0, 0], axis_W_desired=desired, orientation_gain=10.0
    )
    _PLANT.SetPositions(context, arm.model_instance, q_d)
    X_WE = arm.tool_frame.CalcPoseInWorld(context)
    assert np.degrees(np.arccos(X_WE.rotation().matrix()[:, 0] @ desired)) < 0.5
    assert np.linalg.norm(X_WE.translation() - p_WE(q0)) < 1e-4


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"axis_E": [0.0, 0.0, 1e-12]}, "axis_E must be a nonzero direction"),
        ({"axis_E": [0.0, 1.0]}, "axis_E must have shape"),
        ({"axis_W_desired": [np.nan, 0.0, 1.0]}, "axis_W_desired must be finite"),
        ({"axis_W_desired": [0.0, 0.0, 0.0]}, "axis_W_desired must be a nonzero direction"),
        ({"orientation_gain": -1.0}, "orientation_gain"),
        ({"orientation_gain": 2000.0}, "orientation_gain \\* period must be <= 1"),
    ],
)
def test_bad_axis_parameters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        make_clik(**kwargs)


def _draw_first_stroke(orientation_gain):
    """The shipped drawing scenario (its sheet where a vertical pen reaches every stroke)
    on the product's station: plan -> Clik -> PD (K = 100, ``build_plan_follower``) until
    the end of stroke 1, the arm started pen-down by IK. Returns the pen tilt (rad), the tip
    and the contact force, logged."""
    from pydrake.systems.primitives import LogVectorOutput

    from hemg_drake.diagrams.plan_follower import build_plan_follower
    from hemg_drake.scenario import load_scenario, shipped_scenario
    from hemg_drake.tasks.plans import drawing_steps

    scenario = load_scenario(
        shipped_scenario("drawing"), overrides=[f"clik.orientation_gain={orientation_gain}"]
    )
    follower = build_plan_follower(scenario, gain=100.0)
    builder = DiagramBuilder()
    diagram = builder.AddSystem(follower.diagram)
    state_log = LogVectorOutput(diagram.GetOutputPort("arm_state"), builder, 0.01)
    force_log = LogVectorOutput(diagram.GetOutputPort("f_WE"), builder, 0.01)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(drawing_steps(follower.plan)[1])
    context = simulator.get_context()
    plant, arm = follower.plant, follower.station.arm
    poses = [_tool_axis_and_point(plant, arm, q) for q in state_log.FindLog(context).data()[:7].T]
    tilt = np.array([_tilt(axis) for axis, _ in poses])
    p_WP = np.array([p for _, p in poses])
    return tilt, p_WP, force_log.FindLog(context).data().T, follower.plan


def test_pen_stays_vertical_while_drawing_with_the_axis_task():
    """Issue 13: stroke 1 (an 11 cm line) with the pen axis task; the measured arm's pen
    within 5 deg of vertical whenever it touches, and the stroke drawn as planned."""
    from hemg_drake.viz.ink import in_contact, ink_strokes

    tilt, p_WP, f_WP, plan = _draw_first_stroke(orientation_gain=10.0)
    touching = in_contact(f_WP)
    assert touching.sum() > 100
    assert np.degrees(tilt[touching].max()) < 5.0
    (ink,) = ink_strokes(np.arange(len(tilt)) * 0.01, p_WP, touching)
    # The planned line: from the first pen-down corner to the next, within 5 mm.
    first = plan.pen_down.index(True)
    start, end = plan.points[first + 1, :2], plan.points[first + 2, :2]
    assert np.linalg.norm(ink[0, :2] - start) < 0.005 and np.linalg.norm(ink[-1, :2] - end) < 0.005
    along = (ink[:, :2] - start) @ (end - start) / np.linalg.norm(end - start)
    u = (end - start) / np.linalg.norm(end - start)
    across = u[0] * (ink[:, 1] - start[1]) - u[1] * (ink[:, 0] - start[0])
    assert np.all(np.abs(across) < 0.005) and np.all(np.diff(along) > -1e-4)
    # (The position-only law from the same start: up to 12 deg on the strokes,
    # benchmarks/bench_clik.py.)


def test_axis_directions_are_normalised():
    q0 = Q_PEN_DOWN + np.array([0.0, 0.0, 0.0, 0.0, 0.1, 0.1, 0.0])
    _, clik, _ = make_clik()
    target = p_WE(q0)
    unit = run_clik(target, q0, 0.01, orientation_gain=5.0)[0]
    scaled = run_clik(target, q0, 0.01, axis_E=[0, 0, 3], axis_W_desired=[0, 0, -0.5],
                      orientation_gain=5.0)[0]
    np.testing.assert_allclose(scaled, unit, rtol=0, atol=1e-14)
    assert np.linalg.norm(unit - q0) > 1e-3


def _axis_rates_by_the_docstring(q, target, gain, axis_gain, axis_E, axis_W):
    """The class docstring's tool-axis law written with numpy's solves and Drake's spatial
    Jacobian on the test's plant (no block algebra)."""
    from hemg_drake.control.clik import AXIS_DAMPING, NULL_SPACE_DAMPING

    _PLANT.SetPositions(_CONTEXT, _ARM.model_instance, q)
    W = _PLANT.world_frame()
    J = _PLANT.CalcJacobianSpatialVelocity(
        _CONTEXT, JacobianWrtVariable.kV, _ARM.tool_frame, np.zeros(3), W, W
    )
    Jw, Jv = J[:3], J[3:]
    X_WE = _ARM.tool_frame.CalcPoseInWorld(_CONTEXT)
    e = target - X_WE.translation()
    a = X_WE.rotation().matrix() @ axis_E
    qdot_p = gain * Jv.T @ e
    N = np.eye(7) - Jv.T @ np.linalg.solve(Jv @ Jv.T + NULL_SPACE_DAMPING**2 * np.eye(3), Jv)
    P = np.eye(3) - np.outer(a, a)
    A = P @ Jw @ N
    cross = np.cross(a, axis_W)
    e_a = np.arctan2(np.linalg.norm(cross), a @ axis_W) * cross / np.linalg.norm(cross)
    r = axis_gain * e_a - P @ Jw @ qdot_p
    return qdot_p + A.T @ np.linalg.solve(A @ A.T + AXIS_DAMPING**2 * np.eye(3), r)


def test_axis_step_is_the_documented_law():
    """One update with the axis task against the law as the docstring states it."""
    q0 = Q_PEN_DOWN + np.array([0.1, 0.0, -0.2, 0.0, 0.2, 0.2, 0.0])
    target = p_WE(q0) + np.array([0.01, -0.005, 0.004])
    axis_E, axis_W = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])
    _, v_d, _, arm = run_clik(target, q0, 0.5e-3, gain=20.0, orientation_gain=2.0)
    expected = _axis_rates_by_the_docstring(q0, target, 20.0, 2.0, axis_E, axis_W)
    assert np.all(np.abs(expected) < arm.velocity_limit)  # no limit acts
    np.testing.assert_allclose(v_d, expected, rtol=1e-9, atol=1e-9)
