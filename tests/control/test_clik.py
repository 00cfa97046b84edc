"""CLIK (eq. 21) on the Baxter arm, driven through Drake."""

import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from hemg_drake.control.clik import Clik
from hemg_drake.robots.baxter import add_baxter_arm


def make_clik(**kwargs):
    """A kinematic-only diagram: the CLIK reads a fixed arm state and a fixed target."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    arm = add_baxter_arm(plant)
    plant.Finalize()
    clik = builder.AddSystem(
        Clik(plant=plant, model_instance=arm.model_instance, frame_E=arm.tool_frame, **kwargs)
    )
    builder.ExportInput(clik.GetInputPort("p_WE_desired"), "p_WE_desired")
    builder.ExportInput(clik.GetInputPort("state"), "state")
    builder.ExportOutput(clik.GetOutputPort("q_desired"), "q_desired")
    builder.ExportOutput(clik.GetOutputPort("v_desired"), "v_desired")
    diagram = builder.Build()
    return diagram, clik, arm


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
    target = clik.p_WE(q_goal)
    assert np.linalg.norm(target - clik.p_WE(q0)) > 0.1  # a real move
    q_d, v_d, clik, _ = run_clik(target, q0, 3.0, method=method, gain=gain)
    assert np.linalg.norm(clik.p_WE(q_d) - target) < 1e-3
    assert np.linalg.norm(v_d) < 0.05  # settled


def test_starts_from_the_measured_state():
    q0 = np.array([0.1, -0.4, 0.1, 0.9, 0.1, 1.0, 0.2])
    _, clik, _ = make_clik()
    q_d, v_d, _, _ = run_clik(clik.p_WE(q0), q0, 0.0)
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
    assert np.linalg.norm(clik.p_WE(q_d) - target) < np.linalg.norm(clik.p_WE(q0) - target)


def test_transpose_step_is_eq_21():
    """Two updates equal q + dt * K * J^T e, computed independently with the plant."""
    q0 = np.array([0.2, -0.5, 0.1, 0.8, 0.0, 1.0, 0.0])
    _, clik, _ = make_clik()
    # 2 cm away: small enough that no velocity limit scales the step.
    target = clik.p_WE(q0) + np.array([0.02, -0.01, 0.01])
    # Updates fire at t = 0 and t = 1 ms before 1.5 ms.
    q_d, v_d, clik, arm = run_clik(target, q0, 1.5e-3, gain=20.0)
    assert np.all(np.abs(v_d) < 0.5 * arm.velocity_limit)

    plant = clik._plant
    context = plant.CreateDefaultContext()  # not the CLIK's own

    def step(q):
        plant.SetPositions(context, arm.model_instance, q)
        W = plant.world_frame()
        p = plant.CalcPointsPositions(context, arm.tool_frame, np.zeros(3), W).ravel()
        J = plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kV, arm.tool_frame, np.zeros(3), W, W
        )
        return q + 1e-3 * 20.0 * J.T @ (target - p)

    q1 = step(q0)
    q2 = step(q1)
    np.testing.assert_allclose(q_d, q2, atol=1e-12)
    np.testing.assert_allclose(v_d, (q2 - q1) / 1e-3, atol=1e-9)


def test_nan_target_holds_the_reference():
    q0 = np.array([0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0])
    q_d, v_d, _, _ = run_clik(np.array([np.nan, 0.0, 0.0]), q0, 0.05)
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
