"""Force sensors through Drake: a ball resting on a box (point and hydroelastic), a bushing."""

import numpy as np
import pytest
from pydrake.geometry import (
    AddCompliantHydroelasticProperties,
    AddContactMaterial,
    AddRigidHydroelasticProperties,
    Box,
    ProximityProperties,
    Sphere,
)
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, CoulombFriction
from pydrake.multibody.tree import LinearBushingRollPitchYaw, SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from hemg_drake.tasks.sensors import BushingForceSensor, ContactForceSensor

MASS = 0.5
RADIUS = 0.05
G = 9.81


def _ball_on_box(hydroelastic, *, drop=0.0):
    """A free ball above a welded box (its top at z = 0), 1 ms discrete; sensors on both."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    ball = plant.AddRigidBody("ball", SpatialInertia.SolidSphereWithMass(MASS, RADIUS))
    ball_props, box_props = ProximityProperties(), ProximityProperties()
    for props in (ball_props, box_props):
        AddContactMaterial(
            dissipation=20.0, point_stiffness=1e5, friction=CoulombFriction(0.5, 0.5),
            properties=props,
        )
    if hydroelastic:
        AddCompliantHydroelasticProperties(RADIUS, 1e6, ball_props)
        AddRigidHydroelasticProperties(box_props)
    plant.RegisterCollisionGeometry(ball, RigidTransform(), Sphere(RADIUS), "ball", ball_props)
    plant.RegisterCollisionGeometry(
        plant.world_body(), RigidTransform([0, 0, -0.05]), Box(1, 1, 0.1), "box", box_props
    )
    plant.Finalize()
    plant.SetDefaultFloatingBaseBodyPose(ball, RigidTransform([0, 0, RADIUS + drop]))
    sensors = []
    for body in (ball, plant.world_body()):
        sensor = builder.AddSystem(ContactForceSensor(plant=plant, body=body))
        builder.Connect(plant.get_contact_results_output_port(), sensor.contact_results_input)
        sensors.append(sensor)
    diagram = builder.Build()
    return diagram, plant, sensors


@pytest.mark.parametrize("hydroelastic", [False, True])
def test_resting_ball_feels_its_weight(hydroelastic):
    diagram, plant, (on_ball, on_box) = _ball_on_box(hydroelastic)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.5)
    context = simulator.get_context()
    results = plant.get_contact_results_output_port().Eval(plant.GetMyContextFromRoot(context))
    assert (results.num_hydroelastic_contacts() == 1) == hydroelastic
    assert (results.num_point_pair_contacts() == 1) != hydroelastic
    f_ball = on_ball.f_WE_output.Eval(on_ball.GetMyContextFromRoot(context))
    f_box = on_box.f_WE_output.Eval(on_box.GetMyContextFromRoot(context))
    # At rest the contact carries the weight: up on the ball, down on the box.
    np.testing.assert_allclose(f_ball, [0, 0, MASS * G], atol=0.01 * MASS * G)
    np.testing.assert_allclose(f_box, -f_ball, atol=1e-12)


def test_no_contact_no_force():
    diagram, _, (on_ball, _) = _ball_on_box(False, drop=0.5)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.05)
    f = on_ball.f_WE_output.Eval(on_ball.GetMyContextFromRoot(simulator.get_context()))
    np.testing.assert_array_equal(f, np.zeros(3))


def test_contact_sensor_errors():
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    body = plant.AddRigidBody("bare", SpatialInertia.SolidSphereWithMass(1.0, 0.1))
    with pytest.raises(ValueError, match="finalized"):
        ContactForceSensor(plant=plant, body=body)
    plant.Finalize()
    with pytest.raises(ValueError, match="'bare' has no collision geometry"):
        ContactForceSensor(plant=plant, body=body)


def test_bushing_force_is_minus_stiffness_and_damping_in_world():
    k, c = np.array([300.0, 300.0, 300.0]), np.array([7.0, 7.0, 7.0])
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    body = plant.AddRigidBody("block", SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.1))
    bushing = plant.AddForceElement(
        LinearBushingRollPitchYaw(
            plant.world_frame(), body.body_frame(), np.zeros(3), np.zeros(3), k, c
        )
    )
    with pytest.raises(ValueError, match="finalized"):
        BushingForceSensor(plant=plant, bushing=bushing)
    plant.Finalize()
    sensor = builder.AddSystem(BushingForceSensor(plant=plant, bushing=bushing))
    builder.Connect(plant.get_state_output_port(), sensor.state_input)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    # C turned well away from A, displaced and moving (no spin): the force in W does not
    # depend on the turn for an isotropic bushing, but Drake reports it in C.
    p_AC = np.array([0.02, -0.03, 0.01])
    v_AC = np.array([0.1, 0.05, -0.2])
    plant.SetFreeBodyPose(plant_context, body, RigidTransform(RollPitchYaw(0.4, -0.3, 0.9), p_AC))
    plant.SetFreeBodySpatialVelocity(plant_context, body, SpatialVelocity(np.zeros(3), v_AC))
    f_WE = sensor.f_WE_output.Eval(sensor.GetMyContextFromRoot(context))
    np.testing.assert_allclose(f_WE, -k * p_AC - c * v_AC, rtol=1e-9, atol=1e-12)
