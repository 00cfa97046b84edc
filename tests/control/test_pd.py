"""VariableGainPd (eq. 20) on the Baxter arm: its numpy twin, holding, sag, stiffness, limits."""

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    ExternallyAppliedSpatialForce,
    MultibodyPlant,
)
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource

from hemg_drake.control.pd import GAIN_RANGE, STIFFNESS_SCALE, VariableGainPd, pd_gains, pd_torque
from hemg_drake.robots.baxter import add_baxter_arm


def _build(gain=50.0, *, gravity_compensation=True, q_desired=None, force_W=None):
    """Arm at 1 ms + PD held at q_desired (home by default); optional force at the tool point."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    arm = add_baxter_arm(plant)
    plant.Finalize()
    pd = builder.AddSystem(
        VariableGainPd(plant=plant, arm=arm, gain=gain, gravity_compensation=gravity_compensation)
    )
    q_desired = arm.home_positions if q_desired is None else q_desired
    target = builder.AddSystem(ConstantVectorSource(q_desired))
    builder.Connect(target.get_output_port(), pd.q_desired_input)
    builder.Connect(plant.get_state_output_port(arm.model_instance), pd.state_input)
    builder.Connect(pd.torque_output, plant.get_actuation_input_port(arm.model_instance))
    if force_W is not None:
        push = ExternallyAppliedSpatialForce()
        push.body_index = arm.hand_frame.body().index()
        push.p_BoBq_B = arm.tool_frame.GetFixedPoseInBodyFrame().translation()
        push.F_Bq_W = SpatialForce(np.zeros(3), np.asarray(force_W, dtype=float))
        source = builder.AddSystem(ConstantValueSource(AbstractValue.Make([push])))
        builder.Connect(source.get_output_port(), plant.get_applied_spatial_force_input_port())
    diagram = builder.Build()
    return diagram, plant, arm, pd


def _simulate(diagram, plant, arm, q0, duration):
    """Start at rest at q0, run; return tool displacement (3,), final q, final v."""
    simulator = Simulator(diagram)
    plant_context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    plant.SetPositions(plant_context, arm.model_instance, q0)
    p_WT0 = plant.CalcRelativeTransform(plant_context, plant.world_frame(), arm.tool_frame)
    simulator.AdvanceTo(duration)
    p_WT1 = plant.CalcRelativeTransform(plant_context, plant.world_frame(), arm.tool_frame)
    return (
        p_WT1.translation() - p_WT0.translation(),
        plant.GetPositions(plant_context, arm.model_instance),
        plant.GetVelocities(plant_context, arm.model_instance),
    )


def test_pd_gains_by_hand():
    kp, kd = pd_gains(50.0, np.array([20.0, 0.1]), np.array([2.0, 5e-4]), 1.0)
    np.testing.assert_allclose(kp, [1000.0, 5.0])
    np.testing.assert_allclose(kd, [2 * np.sqrt(2000.0), 2 * np.sqrt(2.5e-3)])
    tau = pd_torque(
        np.zeros(2), np.array([0.0, 1.0]), np.full(2, 0.1), np.zeros(2), kp, kd,
        np.array([50.0, 15.0]), 1.0,
    )
    np.testing.assert_allclose(tau, [50.0, 0.1 * 5.0 - kd[1] + 1.0])


@pytest.mark.parametrize("gravity_compensation, damping_ratio", [(True, 1.0), (False, 0.7)])
def test_torque_is_the_documented_law_by_hand(gravity_compensation, damping_ratio):
    # The module docstring's law, written here without pd_gains / pd_torque:
    # k_j = K s_j, d_j = 2 zeta sqrt(k_j M_jj(q)), tau = k (q_d - q) + d (v_d - v) - g(q),
    # clipped at the effort limits; M and g from Drake on a fresh context of the plant.
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    arm = add_baxter_arm(plant)
    plant.Finalize()
    pd = VariableGainPd(
        plant=plant, arm=arm, gravity_compensation=gravity_compensation,
        damping_ratio=damping_ratio,
    )
    q = arm.home_positions + np.array([0.01, -0.02, 0.015, 0.0, -0.01, 0.02, 0.03])
    v = np.array([0.1, -0.05, 0.2, -0.1, 0.0, 0.3, -0.2])
    q_desired = arm.home_positions + np.array([0.0, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0])
    v_desired = np.array([0.0, 0.1, 0.0, 0.0, -0.2, 0.0, 0.5])
    K = 120.0
    context = pd.CreateDefaultContext()
    pd.state_input.FixValue(context, np.concatenate([q, v]))
    pd.q_desired_input.FixValue(context, q_desired)
    pd.v_desired_input.FixValue(context, v_desired)
    pd.gain_input.FixValue(context, [K])
    torque = pd.torque_output.Eval(context)

    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, q)
    M_jj = np.diag(plant.CalcMassMatrix(plant_context))
    g = plant.CalcGravityGeneralizedForces(plant_context)  # tau_g: the PD adds -tau_g
    s = np.array([20.0, 20.0, 10.0, 10.0, 2.0, 2.0, 0.1])
    limit = np.asarray(arm.effort_limit)
    expected = np.empty(7)
    for j in range(7):
        k_j = K * s[j]
        d_j = 2.0 * damping_ratio * np.sqrt(k_j * M_jj[j])
        tau = k_j * (q_desired[j] - q[j]) + d_j * (v_desired[j] - v[j])
        if gravity_compensation:
            tau -= g[j]
        expected[j] = min(max(tau, -limit[j]), limit[j])
    # Joint e1 is 0.3 rad off at K s = 1200 N m/rad: saturated; the others are not.
    assert expected[3] == limit[3]
    assert np.all(np.abs(np.delete(expected, 3)) < np.delete(limit, 3))
    np.testing.assert_allclose(torque, expected, rtol=1e-12, atol=1e-12)


def test_system_matches_numpy_twin_with_gain_port():
    # The compiled kernel against the numpy forms (pd_gains, pd_torque; checked by hand in
    # test_pd_gains_by_hand), and the gain port overriding the constructor's gain. The law
    # itself: test_torque_is_the_documented_law_by_hand.
    diagram, plant, arm, pd = _build(gain=50.0)
    rng = np.random.default_rng(3)
    q = arm.home_positions + rng.uniform(-0.01, 0.01, 7)  # small errors: no saturation
    v = rng.uniform(-0.1, 0.1, 7)
    q_desired = arm.home_positions
    v_desired = rng.uniform(-0.1, 0.1, 7)
    context = diagram.CreateDefaultContext()
    pd_context = pd.GetMyMutableContextFromRoot(context)
    pd.state_input.FixValue(pd_context, np.concatenate([q, v]))
    pd.q_desired_input.FixValue(pd_context, q_desired)
    pd.v_desired_input.FixValue(pd_context, v_desired)
    pd.gain_input.FixValue(pd_context, [80.0])  # overrides the constructor's 50
    torque = pd.torque_output.Eval(pd_context)

    # Independent reference: M and g from a fresh context of the plant.
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, q)
    kp, kd = pd_gains(80.0, STIFFNESS_SCALE, np.diag(plant.CalcMassMatrix(plant_context)), 1.0)
    gravity_torque = -plant.CalcGravityGeneralizedForces(plant_context)
    expected = pd_torque(q, v, q_desired, v_desired, kp, kd, arm.effort_limit, gravity_torque)
    np.testing.assert_allclose(torque, expected, rtol=1e-12, atol=1e-12)
    assert np.all(np.abs(torque) < arm.effort_limit)  # the comparison did not just hit limits


def test_holds_configuration_with_gravity_compensation():
    diagram, plant, arm, _ = _build(gain=50.0)
    drift, _, _ = _simulate(diagram, plant, arm, arm.home_positions, 5.0)
    assert np.linalg.norm(drift) < 1e-3


def test_sags_without_gravity_compensation():
    diagram, plant, arm, _ = _build(gain=50.0, gravity_compensation=False)
    drift, _, _ = _simulate(diagram, plant, arm, arm.home_positions, 5.0)
    # Gravity on s1 (~48 N m) against 1000 N m/rad: about 5 cm at the tool, downwards.
    assert np.linalg.norm(drift) > 0.02
    assert drift[2] < -0.02


@pytest.mark.parametrize("gain", [GAIN_RANGE[0], 50.0, GAIN_RANGE[1]])
def test_stable_over_gain_range(gain):
    # Start 0.2 rad off on every joint; an unstable explicit PD ends in a fast limit cycle.
    diagram, plant, arm, _ = _build(gain=gain)
    _, q, v = _simulate(diagram, plant, arm, arm.home_positions + 0.2, 3.0)
    assert np.max(np.abs(q - arm.home_positions)) < 0.05
    assert np.max(np.abs(v)) < 0.05


def test_static_deflection_scales_with_inverse_gain():
    force_W = np.array([0.0, 0.0, -10.0])  # 10 N down at the tool point
    deflections = {}
    for gain in (50.0, 200.0):
        diagram, plant, arm, _ = _build(gain=gain, force_W=force_W)
        drift, _, v = _simulate(diagram, plant, arm, arm.home_positions, 2.0)
        assert np.max(np.abs(v)) < 1e-4  # settled: a static deflection
        deflections[gain] = drift
    # Stiffness K S gives, for small deflections, dx = J (K S)^-1 J^T F (an independent model).
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, arm.home_positions)
    J = plant.CalcJacobianTranslationalVelocity(
        plant_context, JacobianWrtVariable.kV, arm.tool_frame, np.zeros(3),
        plant.world_frame(), plant.world_frame(),
    )
    for gain, drift in deflections.items():
        predicted = J @ ((J.T @ force_W) / (gain * STIFFNESS_SCALE))
        np.testing.assert_allclose(drift, predicted, rtol=0.05, atol=2e-4)
    # 4x the gain, 1/4 of the deflection, within 5 % (the rest is geometric nonlinearity).
    ratio = np.linalg.norm(deflections[50.0]) / np.linalg.norm(deflections[200.0])
    assert ratio == pytest.approx(4.0, rel=0.05)


def test_torque_saturates_at_effort_limits():
    diagram, plant, arm, pd = _build(gain=GAIN_RANGE[1])
    context = diagram.CreateDefaultContext()
    pd_context = pd.GetMyMutableContextFromRoot(context)
    q = arm.home_positions
    pd.state_input.FixValue(pd_context, np.concatenate([q, np.zeros(7)]))
    signs = np.array([1, -1, 1, -1, 1, -1, 1])
    pd.q_desired_input.FixValue(pd_context, q + 1.0 * signs)
    torque = pd.torque_output.Eval(pd_context)
    np.testing.assert_allclose(torque[:6], signs[:6] * arm.effort_limit[:6])
    # The last wrist roll is the softest joint (0.1 x 500 = 50 N m/rad): 50 N m still > 15 N m.
    assert torque[6] == pytest.approx(arm.effort_limit[6])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"gain": 0.0}, "gain"),
        ({"gain": float("nan")}, "gain"),
        ({"stiffness_scale": np.ones(6)}, "stiffness_scale"),
        ({"stiffness_scale": [1.0] * 6 + [np.inf]}, "stiffness_scale"),
        ({"damping_ratio": -1.0}, "damping_ratio"),
        ({"damping_ratio": float("nan")}, "damping_ratio"),
    ],
)
def test_bad_parameters(kwargs, message):
    _, plant, arm, _ = _build()
    with pytest.raises(ValueError, match=message):
        VariableGainPd(plant=plant, arm=arm, **kwargs)


def test_unfinalized_plant_is_rejected():
    plant = MultibodyPlant(1e-3)
    arm = add_baxter_arm(plant)
    with pytest.raises(ValueError, match="finalized"):
        VariableGainPd(plant=plant, arm=arm)


@pytest.mark.parametrize(
    "gain, q_offset, message",
    [(float("nan"), 0.0, "gain input"), (-1.0, 0.0, "gain input"), (50.0, np.nan, "q_desired")],
)
def test_bad_inputs_are_rejected(gain, q_offset, message):
    diagram, _, arm, pd = _build()
    pd_context = pd.GetMyMutableContextFromRoot(diagram.CreateDefaultContext())
    pd.state_input.FixValue(pd_context, np.zeros(14))
    pd.q_desired_input.FixValue(pd_context, arm.home_positions + q_offset)
    pd.gain_input.FixValue(pd_context, [gain])
    with pytest.raises(ValueError, match=message):
        pd.torque_output.Eval(pd_context)
