"""The push at the tool point: tau = J^T F, checked against the virtual work of the tool
point's displacement (finite differences of its position, through Drake's forward
kinematics) and against Drake's own spatial-force path (MultibodyForces); its time course,
its switch, and a scalar conversion."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.tree import MultibodyForces
from pydrake.systems.framework import DiagramBuilder

from hemg_drake.control.clik import velocity_columns
from hemg_drake.control.push import ToolPointForce, ToolPointForce_, push_trajectory
from hemg_drake.robots.baxter import add_baxter_arm, make_arm_controller_plant
from hemg_drake.tasks.cotter_pin import add_cotter_pin_scene

Q = np.array([0.3, -0.5, 0.2, 1.1, -0.4, 0.9, 0.1])
F_W = np.array([3.0, 40.0, -7.0])


@pytest.fixture(scope="module")
def station_plant():
    """A plant with the arm and the cotter pin (8 velocities: the arm's 7 and the pin's)."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    arm = add_baxter_arm(plant)
    add_cotter_pin_scene(plant, arm)
    plant.Finalize()
    return plant, arm


def _push(plant, arm):
    controller_plant, controller_arm = make_arm_controller_plant()
    return ToolPointForce(
        controller_plant=controller_plant, arm=controller_arm,
        columns=velocity_columns(plant, arm.model_instance),
        num_velocities=plant.num_velocities(),
    )  # fmt: skip


def _output(system, q, f_W, v=np.zeros(7)):
    context = system.CreateDefaultContext()
    system.arm_state_input.FixValue(context, np.concatenate([q, v]))
    system.f_W_input.FixValue(context, f_W)
    return system.generalized_force_output.Eval(context), context


def test_torque_is_the_virtual_work_of_the_tool_point(station_plant):
    plant, arm = station_plant
    tau, _ = _output(_push(plant, arm), Q, F_W)
    assert tau.shape == (plant.num_velocities(),)
    columns = velocity_columns(plant, arm.model_instance)
    # Hand reference: tau_j = F . dp_WE/dq_j, central differences of the tool point's
    # position (forward kinematics only; no Jacobian).
    context = plant.CreateDefaultContext()
    world = plant.world_frame()

    def p_WE(q):
        plant.SetPositions(context, arm.model_instance, q)
        return plant.CalcPointsPositions(context, arm.tool_frame, np.zeros(3), world)[:, 0]

    h = 1e-6
    expected = [F_W @ (p_WE(Q + h * e) - p_WE(Q - h * e)) / (2 * h) for e in np.eye(7)]
    np.testing.assert_allclose(tau[columns], expected, rtol=1e-6, atol=1e-6)
    others = np.ones(plant.num_velocities(), dtype=bool)
    others[columns] = False
    np.testing.assert_array_equal(tau[others], 0.0)  # the pin's slide is not pushed


def test_torque_matches_drakes_spatial_force_path(station_plant):
    plant, arm = station_plant
    tau, _ = _output(_push(plant, arm), Q, F_W, v=np.full(7, 0.2))
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, arm.model_instance, Q)
    forces = MultibodyForces(plant)
    body = arm.tool_frame.body()
    p_BE = arm.tool_frame.GetFixedPoseInBodyFrame().translation()
    # AddInForce takes the point's offset from Bo expressed in the force's frame (W here).
    p_BE_W = body.body_frame().CalcPoseInWorld(context).rotation() @ p_BE
    body.AddInForce(context, p_BE_W, SpatialForce(np.zeros(3), F_W), plant.world_frame(), forces)
    # Drake: tau_applied = J^T F through its own recursion (velocities do not enter).
    expected = plant.CalcGeneralizedForces(context, forces)
    np.testing.assert_allclose(tau, expected, rtol=1e-9, atol=1e-9)


def test_switched_off_it_applies_nothing_and_it_converts(station_plant):
    plant, arm = station_plant
    system = _push(plant, arm)
    context = system.CreateDefaultContext()
    system.arm_state_input.FixValue(context, np.concatenate([Q, np.zeros(7)]))
    system.f_W_input.FixValue(context, F_W)
    system.set_enabled(context, False)
    np.testing.assert_array_equal(system.generalized_force_output.Eval(context), 0.0)
    converted = system.ToAutoDiffXd()
    assert isinstance(converted, ToolPointForce_[AutoDiffXd])
    system.set_enabled(context, True)
    ad_context = converted.CreateDefaultContext()
    converted.arm_state_input.FixValue(ad_context, [AutoDiffXd(x) for x in np.r_[Q, np.zeros(7)]])
    converted.f_W_input.FixValue(ad_context, [AutoDiffXd(f) for f in F_W])
    values = [t.value() for t in converted.generalized_force_output.Eval(ad_context)]
    np.testing.assert_allclose(values, system.generalized_force_output.Eval(context), rtol=1e-12,
                               atol=1e-12)


def test_push_trajectory_holds_the_force_for_its_duration():
    trajectory = push_trajectory(F_W, 2.0, 0.3)
    for t, on in [(0.0, False), (1.999, False), (2.0, True), (2.299, True), (2.3, False),
                  (5.0, False)]:  # fmt: skip
        np.testing.assert_array_equal(trajectory.value(t)[:, 0], F_W if on else 0.0)
    at_once = push_trajectory(F_W, 0.0, 0.3)
    np.testing.assert_array_equal(at_once.value(0.0)[:, 0], F_W)
    np.testing.assert_array_equal(at_once.value(0.31)[:, 0], 0.0)
    with pytest.raises(ValueError, match="push duration"):
        push_trajectory(F_W, 1.0, 0.0)
