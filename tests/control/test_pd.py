"""VariableGainPd (eq. 20) on the Baxter arm through Drake: the law by hand, holding, sag,
stiffness, limits, AutoDiffXd slopes and clones."""

import dataclasses as dc

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    ExternallyAppliedSpatialForce,
    MultibodyPlant,
)
from pydrake.multibody.tree import JacobianWrtVariable, SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource

from hemg_drake.control.config import GAIN_RANGE, PdConfig
from hemg_drake.control.pd import VariableGainPd, add_variable_gain_pd
from hemg_drake.robots.baxter import add_baxter_arm, make_arm_controller_plant

# PdConfig's default per-joint stiffness per unit of K, written out (s0 s1 e0 e1 w0 w1 w2).
SCALE = np.array([20.0, 20.0, 10.0, 10.0, 2.0, 2.0, 0.1])


def _build(gain=50.0, *, gravity_compensation=True, q_desired=None, force_W=None):
    """Arm at 1 ms + PD held at q_desired (home by default); optional force at the tool point."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    arm = add_baxter_arm(plant)
    plant.Finalize()
    controller_plant, controller_arm = make_arm_controller_plant()
    config = PdConfig(gain=gain, gravity_compensation=gravity_compensation)
    pd = add_variable_gain_pd(
        builder, plant=controller_plant, arm=controller_arm,
        state_port=plant.get_state_output_port(arm.model_instance), config=config,
    )  # fmt: skip
    q_desired = arm.home_positions if q_desired is None else q_desired
    target = builder.AddSystem(ConstantVectorSource(q_desired))
    builder.Connect(target.get_output_port(), pd.q_desired_input)
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


def _reference_plant():
    """M(q) and g(q) from a plant the PD never sees: the arm behind a free body, so that the
    arm's velocities are not the plant's first (and its columns must be picked by joint)."""
    plant = MultibodyPlant(1e-3)
    plant.AddRigidBody("ball", SpatialInertia.SolidSphereWithMass(2.0, 0.1))
    arm = add_baxter_arm(plant)
    plant.Finalize()
    context = plant.CreateDefaultContext()

    def mass_and_gravity(q):
        plant.SetPositions(context, arm.model_instance, q)
        M = plant.CalcMassMatrix(context)
        g = plant.CalcGravityGeneralizedForces(context)
        columns = [plant.GetJointByName(name).velocity_start() for name in arm.joint_names]
        return np.diag(M)[columns], g[columns]

    return mass_and_gravity


# A configuration near home, rates and references: e1 is 0.3 rad off (saturates at K >= 100).
Q = np.array([0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0]) + [0.01, -0.02, 0.015, 0.0, -0.01, 0.02, 0.03]
V = np.array([0.1, -0.05, 0.2, -0.1, 0.0, 0.3, -0.2])
Q_DESIRED = np.array([0.0, -0.55, 0.0, 1.05, 0.0, 1.26, 0.0])
V_DESIRED = np.array([0.0, 0.1, 0.0, 0.0, -0.2, 0.0, 0.5])


def _hand_law(
    K, zeta, M_jj, feedforward, limit, q=Q, v=V, q_d=Q_DESIRED, v_d=V_DESIRED, scale=SCALE
):
    expected = np.empty(7)
    for j in range(7):
        k_j = K * scale[j]
        d_j = 2.0 * zeta * np.sqrt(k_j * M_jj[j])
        tau = k_j * (q_d[j] - q[j]) + d_j * (v_d[j] - v[j]) + feedforward[j]
        expected[j] = min(max(tau, -limit[j]), limit[j])
    return expected


@pytest.mark.parametrize("gravity_compensation, damping_ratio", [(True, 1.0), (False, 0.7)])
def test_torque_is_the_documented_law_by_hand(gravity_compensation, damping_ratio):
    """k_j = K s_j, d_j = 2 zeta sqrt(k_j M_jj(q)), tau = k (q_d - q) + d (v_d - v) - g(q),
    clipped at the effort limits; M and g from another plant (a ball before the arm)."""
    builder = DiagramBuilder()
    controller_plant, arm = make_arm_controller_plant()
    state = builder.AddSystem(ConstantVectorSource(np.concatenate([Q, V])))
    config = PdConfig(damping_ratio=damping_ratio, gravity_compensation=gravity_compensation)
    pd = add_variable_gain_pd(
        builder, plant=controller_plant, arm=arm, state_port=state.get_output_port(),
        config=config,
    )  # fmt: skip
    builder.ExportInput(pd.q_desired_input, "q_desired")
    builder.ExportInput(pd.v_desired_input, "v_desired")
    builder.ExportInput(pd.gain_input, "gain")
    builder.ExportOutput(pd.torque_output, "torque")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    K = 120.0
    diagram.GetInputPort("q_desired").FixValue(context, Q_DESIRED)
    diagram.GetInputPort("v_desired").FixValue(context, V_DESIRED)
    diagram.GetInputPort("gain").FixValue(context, [K])
    torque = diagram.GetOutputPort("torque").Eval(context)

    M_jj, g = _reference_plant()(Q)
    limit = np.asarray(arm.effort_limit)
    expected = _hand_law(K, damping_ratio, M_jj, -g if gravity_compensation else np.zeros(7), limit)
    # Joint e1 is 0.3 rad off at K s = 1200 N m/rad: saturated; the others are not.
    assert expected[3] == limit[3]
    assert np.all(np.abs(np.delete(expected, 3)) < np.delete(limit, 3))
    np.testing.assert_allclose(torque, expected, rtol=1e-12, atol=1e-12)


def test_unconnected_inputs_take_the_configs_gain_and_zero():
    """Without gain, v_desired and feed-forward inputs: K = config.gain, v_d = 0, tau_ff = 0."""
    controller_plant, arm = make_arm_controller_plant()
    pd = VariableGainPd(plant=controller_plant, arm=arm, config=PdConfig(gain=30.0))
    context = pd.CreateDefaultContext()
    q_desired = Q + 0.01  # small errors: nothing saturates
    pd.state_input.FixValue(context, np.concatenate([Q, V]))
    pd.q_desired_input.FixValue(context, q_desired)
    M_jj, _ = _reference_plant()(Q)
    expected = _hand_law(30.0, 1.0, M_jj, np.zeros(7), arm.effort_limit, q_d=q_desired,
                         v_d=np.zeros(7))  # fmt: skip
    np.testing.assert_allclose(pd.torque_output.Eval(context), expected, rtol=1e-12, atol=1e-12)
    # A feed-forward adds before the clip.
    pd.feedforward_input.FixValue(context, np.arange(7.0))
    np.testing.assert_allclose(
        pd.torque_output.Eval(context), expected + np.arange(7.0), rtol=1e-12, atol=1e-12
    )


def test_autodiff_slopes_are_the_laws_derivatives():
    """The PD converted to AutoDiffXd: d tau / d K = s (q_d - q) + d / (2 K) (v_d - v) and
    d tau / d q_d = diag(K s), where nothing saturates (closed forms)."""
    controller_plant, arm = make_arm_controller_plant()
    pd = VariableGainPd(plant=controller_plant, arm=arm).ToAutoDiffXd()
    context = pd.CreateDefaultContext()
    K = 40.0
    q_desired = Q + np.array([0.01, -0.01, 0.02, 0.0, 0.01, -0.02, 0.01])
    # Derivatives with respect to (K, q_d): 8 directions.
    K_ad = InitializeAutoDiff([[K]], num_derivatives=8, deriv_num_start=0)
    q_d_ad = InitializeAutoDiff(q_desired.reshape(-1, 1), num_derivatives=8, deriv_num_start=1)
    pd.gain_input.FixValue(context, K_ad[:, 0])
    pd.q_desired_input.FixValue(context, q_d_ad[:, 0])
    pd.v_desired_input.FixValue(context, [AutoDiffXd(x) for x in V_DESIRED])
    pd.state_input.FixValue(context, [AutoDiffXd(x) for x in np.concatenate([Q, V])])
    torque = pd.torque_output.Eval(context)
    M_jj, _ = _reference_plant()(Q)
    k = K * SCALE
    d = 2.0 * np.sqrt(k * M_jj)
    np.testing.assert_allclose(
        ExtractValue(torque).ravel(), k * (q_desired - Q) + d * (V_DESIRED - V), rtol=1e-12
    )
    gradient = ExtractGradient(torque)
    dtau_dK = SCALE * (q_desired - Q) + d / (2.0 * K) * (V_DESIRED - V)
    np.testing.assert_allclose(gradient[:, 0], dtau_dK, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(gradient[:, 1:], np.diag(k), rtol=1e-12, atol=1e-12)


def test_gains_are_parameters_of_each_context():
    """Two contexts of one diagram, one with set_gains: each gives the hand law with its own
    K, s_j, zeta and limits; a context's Clone keeps them; the AutoDiffXd diagram takes them
    with SetTimeStateAndParametersFrom and gives the same torque."""
    builder = DiagramBuilder()
    controller_plant, arm = make_arm_controller_plant()
    state = builder.AddSystem(ConstantVectorSource(np.concatenate([Q, V])))
    pd = add_variable_gain_pd(
        builder, plant=controller_plant, arm=arm, state_port=state.get_output_port()
    )
    builder.ExportInput(pd.q_desired_input, "q_desired")
    builder.ExportInput(pd.v_desired_input, "v_desired")
    builder.ExportOutput(pd.torque_output, "torque")  # gain unconnected: K is the parameter
    diagram = builder.Build()
    contexts = [diagram.CreateDefaultContext() for _ in range(2)]
    for context in contexts:
        diagram.GetInputPort("q_desired").FixValue(context, Q_DESIRED)
        diagram.GetInputPort("v_desired").FixValue(context, V_DESIRED)
    scale = np.array([15.0, 25.0, 8.0, 12.0, 3.0, 1.0, 0.2])
    limit = np.array([40.0, 30.0, 20.0, 10.0, 5.0, 4.0, 3.0])
    pd.set_gains(
        pd.GetMyMutableContextFromRoot(contexts[1]), gain=70.0, stiffness_scale=scale,
        damping_ratio=0.6, effort_limit=limit,
    )  # fmt: skip
    M_jj, g = _reference_plant()(Q)
    expected = [
        _hand_law(50.0, 1.0, M_jj, -g, np.asarray(arm.effort_limit)),
        _hand_law(70.0, 0.6, M_jj, -g, limit, scale=scale),
    ]
    assert np.abs(expected[0] - expected[1]).min() > 1e-3  # the two laws differ everywhere
    assert 1 <= (np.abs(expected[1]) == limit).sum() < 7  # the new limits clip, not all
    for context, torque in zip(contexts, expected):
        np.testing.assert_allclose(
            diagram.GetOutputPort("torque").Eval(context), torque, rtol=1e-12, atol=1e-12
        )
    clone = contexts[1].Clone()
    np.testing.assert_array_equal(
        diagram.GetOutputPort("torque").Eval(clone),
        diagram.GetOutputPort("torque").Eval(contexts[1]),
    )
    gains = pd.get_gains(pd.GetMyContextFromRoot(clone))
    assert gains["gain"] == 70.0 and gains["damping_ratio"] == 0.6
    np.testing.assert_array_equal(gains["stiffness_scale"], scale)
    np.testing.assert_array_equal(gains["effort_limit"], limit)
    diagram_ad = diagram.ToAutoDiffXd()
    context_ad = diagram_ad.CreateDefaultContext()
    context_ad.SetTimeStateAndParametersFrom(contexts[1])
    diagram_ad.GetInputPort("q_desired").FixValue(context_ad, [AutoDiffXd(x) for x in Q_DESIRED])
    diagram_ad.GetInputPort("v_desired").FixValue(context_ad, [AutoDiffXd(x) for x in V_DESIRED])
    torque_ad = ExtractValue(diagram_ad.GetOutputPort("torque").Eval(context_ad)).ravel()
    np.testing.assert_allclose(torque_ad, expected[1], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"gain": 0.0}, "gain"),
        ({"stiffness_scale": [1.0] * 6}, "stiffness_scale"),
        ({"damping_ratio": float("nan")}, "damping_ratio"),
        ({"effort_limit": [1.0] * 6 + [-1.0]}, "effort_limit"),
    ],
)
def test_bad_gains_are_named(changes, message):
    controller_plant, arm = make_arm_controller_plant()
    pd = VariableGainPd(plant=controller_plant, arm=arm)
    with pytest.raises(ValueError, match=message):
        pd.set_gains(pd.CreateDefaultContext(), **changes)


def test_clones_run_bit_identical():
    diagram, plant, arm, _ = _build(gain=80.0)
    runs = []
    for system in (diagram, diagram.Clone()):
        simulator = Simulator(system)
        its_plant = system.GetSubsystemByName(plant.get_name())  # the clone has its own
        plant_context = its_plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
        its_plant.SetPositions(plant_context, arm.model_instance, arm.home_positions + 0.1)
        simulator.AdvanceTo(0.3)
        runs.append(simulator.get_context().get_discrete_state_vector().CopyToVector())
    np.testing.assert_array_equal(runs[0], runs[1])
    assert np.linalg.norm(runs[0][:7] - arm.home_positions) < 0.1  # it moved


def test_holds_configuration_with_gravity_compensation():
    diagram, plant, arm, _ = _build(gain=50.0)
    drift, _, _ = _simulate(diagram, plant, arm, arm.home_positions, 5.0)
    assert np.linalg.norm(drift) < 1e-3


def test_sags_without_gravity_compensation():
    diagram, plant, arm, _ = _build(gain=50.0, gravity_compensation=False)
    assert not diagram.HasSubsystemNamed("pd_gravity")
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
        predicted = J @ ((J.T @ force_W) / (gain * SCALE))
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
    "changes, message",
    [
        ({"gain": 0.0}, "gain"),
        ({"gain": float("nan")}, "gain"),
        ({"stiffness_scale": [1.0] * 6}, "stiffness_scale"),
        ({"stiffness_scale": [1.0] * 6 + [np.inf]}, "stiffness_scale"),
        ({"damping_ratio": -1.0}, "damping_ratio"),
        ({"damping_ratio": float("nan")}, "damping_ratio"),
    ],
)
def test_bad_parameters(changes, message):
    plant, arm = make_arm_controller_plant()
    with pytest.raises(ValueError, match=message):
        VariableGainPd(plant=plant, arm=arm, config=dc.replace(PdConfig(), **changes))


def test_unfinalized_plant_is_rejected():
    plant = MultibodyPlant(1e-3)
    arm = add_baxter_arm(plant)
    with pytest.raises(ValueError, match="finalized"):
        VariableGainPd(plant=plant, arm=arm)


def test_gravity_needs_a_plant_of_the_arm_alone():
    plant = MultibodyPlant(1e-3)
    plant.AddRigidBody("ball", SpatialInertia.SolidSphereWithMass(2.0, 0.1))
    arm = add_baxter_arm(plant)
    plant.Finalize()
    with pytest.raises(ValueError, match="arm alone"):
        add_variable_gain_pd(
            DiagramBuilder(), plant=plant, arm=arm,
            state_port=plant.get_state_output_port(arm.model_instance),
        )  # fmt: skip


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
