"""CartesianImpedancePd through Drake: the torque against a projector-form hand computation,
eq. 20 recovered with eq. 20's own shape, the static tool compliance K_x^-1 by simulation,
AutoDiffXd."""

import numpy as np
import pytest
from pydrake.autodiffutils import ExtractValue
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, ExternallyAppliedSpatialForce
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource

from hemg_drake.control.config import PdConfig
from hemg_drake.control.impedance import CartesianImpedancePd, add_cartesian_impedance_pd
from hemg_drake.control.pd import VariableGainPd
from hemg_drake.robots.baxter import add_baxter_arm, make_arm_controller_plant

SCALE = np.array([20.0, 20.0, 10.0, 10.0, 2.0, 2.0, 0.1])  # PdConfig's s_j, written out


def kinematics(plant, arm, q):
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    world = plant.world_frame()
    J = plant.CalcJacobianTranslationalVelocity(
        context, JacobianWrtVariable.kV, arm.tool_frame, np.zeros(3), world, world
    )
    return J, plant.CalcMassMatrix(context)


def skewed_shape(seed):
    rng = np.random.default_rng(seed)
    Q = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    return Q @ np.diag([4.0, 1.0, 0.25]) @ Q.T


def fixed(system, q, v, q_desired, gain, shape=None):
    context = system.CreateDefaultContext()
    system.GetInputPort("state").FixValue(context, np.concatenate([q, v]))
    system.GetInputPort("q_desired").FixValue(context, q_desired)
    system.GetInputPort("gain").FixValue(context, [gain])
    if shape is not None:
        system.GetInputPort("stiffness_shape").FixValue(context, np.ravel(shape))
    return context


@pytest.fixture(scope="module")
def arm_and_point():
    plant, arm = make_arm_controller_plant()
    rng = np.random.default_rng(0)
    q = arm.home_positions + 0.2 * rng.standard_normal(7)
    return plant, arm, q, 0.3 * rng.standard_normal(7), q + 0.02 * rng.standard_normal(7)


@pytest.mark.parametrize("gain", [10.0, 150.0])
def test_torque_is_the_cartesian_impedance_by_hand(arm_and_point, gain):
    plant, arm, q, v, q_desired = arm_and_point
    pd = CartesianImpedancePd(plant=plant, arm=arm)
    shape = skewed_shape(1)
    torque = pd.GetOutputPort("torque").Eval(fixed(pd, q, v, q_desired, gain, shape))
    # Hand: J^T K_x J + N^T (K W) N with the W-weighted null-space projector, in numpy.
    J, M = kinematics(plant, arm, q)
    W = np.diag(SCALE)
    C = J @ np.linalg.inv(W) @ J.T
    K_x = gain * 3.0 / np.trace(C) * shape
    N = np.eye(7) - np.linalg.inv(W) @ J.T @ np.linalg.inv(C) @ J
    K_q = J.T @ K_x @ J + N.T @ (gain * W) @ N
    d = 2.0 * PdConfig().damping_ratio * np.sqrt(np.diag(K_q) * np.diag(M))
    limit = arm.effort_limit
    expected = np.clip(K_q @ (q_desired - q) - d * v, -limit, limit)
    np.testing.assert_allclose(torque, expected, rtol=1e-10, atol=1e-10)
    assert np.linalg.eigvalsh(K_q).min() > 0


def test_eq_20s_own_shape_gives_eq_20s_torque(arm_and_point):
    plant, arm, q, v, q_desired = arm_and_point
    J, _ = kinematics(plant, arm, q)
    C = J @ np.diag(1 / SCALE) @ J.T
    own = np.linalg.inv(C) * np.trace(C) / 3.0  # K_x = K_x^0 exactly
    impedance = CartesianImpedancePd(plant=plant, arm=arm)
    scalar = VariableGainPd(plant=plant, arm=arm)
    tau = impedance.GetOutputPort("torque").Eval(fixed(impedance, q, v, q_desired, 50.0, own))
    tau_20 = scalar.GetOutputPort("torque").Eval(fixed(scalar, q, v, q_desired, 50.0))
    np.testing.assert_allclose(tau, tau_20, rtol=1e-9, atol=1e-9)


def test_autodiff_gives_the_same_torque(arm_and_point):
    plant, arm, q, v, q_desired = arm_and_point
    pd = CartesianImpedancePd(plant=plant, arm=arm)
    shape = skewed_shape(2)
    torque = pd.GetOutputPort("torque").Eval(fixed(pd, q, v, q_desired, 80.0, shape))
    other = pd.ToAutoDiffXd()
    value = other.GetOutputPort("torque").Eval(fixed(other, q, v, q_desired, 80.0, shape))
    np.testing.assert_allclose(ExtractValue(value).ravel(), torque, rtol=1e-12)


def deflection(gain, shape, force):
    """Tool displacement (m) of the arm at 1 ms, held at home with gravity compensation by
    the impedance PD, after 3 s of a constant force (N, W) at the tool point."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    arm = add_baxter_arm(plant)
    plant.Finalize()
    controller_plant, controller_arm = make_arm_controller_plant()
    pd = add_cartesian_impedance_pd(
        builder, plant=controller_plant, arm=controller_arm,
        state_port=plant.get_state_output_port(arm.model_instance), config=PdConfig(gain=gain),
    )  # fmt: skip
    for port, value in (("q_desired", arm.home_positions), ("stiffness_shape", shape.ravel())):
        builder.Connect(builder.AddSystem(ConstantVectorSource(value)).get_output_port(),
                        pd.GetInputPort(port))  # fmt: skip
    builder.Connect(pd.torque_output, plant.get_actuation_input_port(arm.model_instance))
    push = ExternallyAppliedSpatialForce()
    push.body_index = arm.hand_frame.body().index()
    push.p_BoBq_B = arm.tool_frame.GetFixedPoseInBodyFrame().translation()
    push.F_Bq_W = SpatialForce(np.zeros(3), force)
    source = builder.AddSystem(ConstantValueSource(AbstractValue.Make([push])))
    builder.Connect(source.get_output_port(), plant.get_applied_spatial_force_input_port())
    simulator = Simulator(builder.Build())
    plant_context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())

    def tool():
        return plant.CalcPointsPositions(
            plant_context, arm.tool_frame, np.zeros(3), plant.world_frame()
        ).ravel()

    start = tool()
    simulator.AdvanceTo(3.0)
    return tool() - start, controller_plant, controller_arm, arm.home_positions


def test_static_tool_compliance_is_the_inverse_of_k_x():
    """A 1 N push along the shape's stiffest and softest axes deflects the tool by
    K_x^-1 f (J K_q^-1 J^T = K_x^-1: the push-through identity), 16x apart."""
    gain, shape = 50.0, skewed_shape(3)
    _, axes = np.linalg.eigh(shape)
    for axis in (axes[:, 0], axes[:, 2]):
        force = 1.0 * axis
        moved, plant, arm, q = deflection(gain, shape, force)
        J, _ = kinematics(plant, arm, q)
        K_x = gain * 3.0 / np.trace(J @ np.diag(1 / SCALE) @ J.T) * shape
        np.testing.assert_allclose(moved, np.linalg.solve(K_x, force), rtol=0.05, atol=2e-5)
