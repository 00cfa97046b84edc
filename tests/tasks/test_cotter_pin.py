"""Cotter pin through Drake: a high constant gain pulls the pin out, a low one does not."""

import itertools

import numpy as np
import pytest
from pydrake.common.yaml import yaml_load_typed
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from hemg_drake.robots.baxter import add_baxter_arm
from hemg_drake.tasks.cotter_pin import (
    PULL_AXIS_W,
    CotterPinParams,
    add_cotter_pin_scene,
    default_cotter_pin_plan,
    detent_force,
    pin_resistance_force,
)
from hemg_drake.tasks.follow import add_plan_follower

LOW_GAIN, HIGH_GAIN = 10.0, 100.0


def _scene(params=None):
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    arm = add_baxter_arm(plant)
    scene = add_cotter_pin_scene(plant, arm, params=params)
    plant.Finalize()
    plant.SetDefaultPositions(arm.model_instance, arm.home_positions)
    return builder, plant, arm, scene


def _pull(gain):
    """Follow the default plan at a constant gain; logs of the pin's [x; xdot] and f_WE."""
    builder, plant, arm, scene = _scene()
    plan = default_cotter_pin_plan()
    add_plan_follower(builder, plant=plant, arm=arm, plan=plan, gain=gain)
    pin_log = LogVectorOutput(plant.get_state_output_port(scene.model_instance), builder, 0.01)
    force_log = LogVectorOutput(scene.force_output_port(builder), builder, 0.01)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(plan.end_time)
    context = simulator.get_context()
    plant_context = plant.GetMyContextFromRoot(context)
    pin = pin_log.FindLog(context)
    return dict(
        scene=scene,
        plant=plant,
        arm=arm,
        plan=plan,
        plant_context=plant_context,
        t=pin.sample_times(),
        x=pin.data()[0],
        f_WE=force_log.FindLog(context).data().T,
    )


@pytest.fixture(scope="module")
def low():
    return _pull(LOW_GAIN)


@pytest.fixture(scope="module")
def high():
    return _pull(HIGH_GAIN)


def test_high_gain_pulls_the_pin_out(high):
    scene = high["scene"]
    assert scene.pin_out(high["plant_context"])
    assert scene.pin_displacement(high["plant_context"]) >= scene.pin_length
    # Held through the hold phase, out during the pull.
    assert np.all(high["x"][high["t"] <= 0.5] < scene.params.detent_length)
    pulled = high["t"] <= high["plan"].times[2]
    assert high["x"][pulled].max() >= scene.pin_length


def test_low_gain_leaves_the_pin_in(low):
    scene = low["scene"]
    assert not scene.pin_out(low["plant_context"])
    # The detent gave only its spring's millimetre: x = (axial pull - weight) / stiffness.
    assert low["x"].max() < scene.params.detent_length
    pull = -low["f_WE"] @ PULL_AXIS_W - 0.1 * 9.81
    assert low["x"].max() == pytest.approx(
        pull.max() / scene.params.detent_stiffness, rel=0.05
    )


def test_interaction_force_against_hold_force(low, high):
    hold = high["scene"].hold_force
    weight = 0.1 * 9.81
    # High gain: the tool is pulled back down (-z) by about the hold force (plus the pin's
    # weight) until the detent lets go, then by little more than the weight.
    peak = high["f_WE"][np.argmax(np.linalg.norm(high["f_WE"], axis=1))]
    assert peak @ PULL_AXIS_W < -0.95 * np.linalg.norm(peak)
    assert hold < np.linalg.norm(peak) < 1.2 * (hold + weight)
    settled = high["t"] >= high["plan"].times[-2]
    np.testing.assert_allclose(high["f_WE"][settled][-1], [0, 0, -weight], atol=0.5)
    # Low gain: the arm pulls hard, but stays under the hold force.
    low_peak = np.linalg.norm(low["f_WE"], axis=1).max()
    assert 0.4 * hold < low_peak < hold
    assert low["f_WE"][-1] @ PULL_AXIS_W < 0


def test_force_sensor_agrees_with_the_grasp_spring(low):
    """At the end of the low-gain run all is still: f_WE = k (p_WR - p_WE), by hand."""
    scene, arm = low["scene"], low["arm"]
    context = low["plant_context"]
    p_WR = scene.ring_frame.CalcPoseInWorld(context).translation()
    p_WE = arm.tool_frame.CalcPoseInWorld(context).translation()
    expected = scene.params.grasp_stiffness * (p_WR - p_WE)
    np.testing.assert_allclose(low["f_WE"][-1], expected, rtol=0.02, atol=0.05)


def test_detent_system_matches_its_twin():
    builder, plant, arm, scene = _scene()
    detent, _ = scene.add_systems(builder)
    assert scene.add_systems(builder)[0] is detent  # added once
    context = detent.CreateDefaultContext()
    index = scene.pin_joint.velocity_start()
    law = dict(hold_force=50.0, detent_length=0.003, detent_stiffness=3e4)
    # Spring, saturated spring, released, pushed back in from a slight overshoot; at rest
    # and sliding out at 0.1 m/s against 20 N s/m of friction.
    cases = ((0.0005, -15.0), (0.002, -50.0), (0.004, 0.0), (-0.0001, 3.0))
    for (x, by_hand), xdot in itertools.product(cases, (0.0, 0.1)):
        detent.pin_state_input.FixValue(context, [x, xdot])
        tau = detent.generalized_force_output.Eval(context)
        assert tau.shape == (plant.num_velocities(),)
        assert tau[index] == pytest.approx(by_hand - 20.0 * xdot)
        assert tau[index] == pytest.approx(detent_force(x, **law) - 20.0 * xdot)
        assert tau[index] == pin_resistance_force(x, xdot, **law, sliding_damping=20.0)
        assert np.count_nonzero(np.delete(tau, index)) == 0


def test_ring_waits_at_the_home_tool_point():
    _, plant, arm, scene = _scene()
    context = plant.CreateDefaultContext()
    p_WE = arm.tool_frame.CalcPoseInWorld(context).translation()
    p_WR = scene.ring_frame.CalcPoseInWorld(context).translation()
    assert np.linalg.norm(p_WE - p_WR) < 0.002
    assert scene.pin_displacement(context) == 0.0
    assert scene.pin_length == pytest.approx(0.05)


def test_plan_has_four_phases_along_the_pull_axis():
    plan = default_cotter_pin_plan()
    params = CotterPinParams()
    assert plan.kinds == ("free", "forceful", "free", "free")
    np.testing.assert_allclose(plan.points[0], params.ring_position)
    np.testing.assert_allclose(plan.points[1], plan.points[0])
    rise = (plan.points - plan.points[0]) @ PULL_AXIS_W
    np.testing.assert_allclose(rise, [0, 0, 0.065, 0.10, 0.10])
    np.testing.assert_allclose(np.cross(plan.points - plan.points[0], PULL_AXIS_W), 0, atol=1e-12)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(hold_force=-1.0), "CotterPinParams.hold_force"),
        (dict(ring_position=[0.6, np.nan, 0.1]), "CotterPinParams.ring_position"),
        (dict(ring_position=[0.6, 0.1]), "CotterPinParams.ring_position"),
        (dict(detent_length=0.06), "CotterPinParams.detent_length"),
        (dict(sliding_damping=-2.0), "CotterPinParams.sliding_damping"),
        (dict(grasp_stiffness=0.0), "CotterPinParams.grasp_stiffness"),
    ],
)
def test_bad_parameters_name_the_field(change, message):
    with pytest.raises(ValueError, match=message):
        CotterPinParams(**change)
    # Values set after construction (as a YAML loader does) are caught by the scene too.
    params = CotterPinParams()
    for name, value in change.items():
        setattr(params, name, value)
    plant = MultibodyPlant(1e-3)
    with pytest.raises(ValueError, match=message):
        add_cotter_pin_scene(plant, add_baxter_arm(plant), params=params)


def test_scene_refuses_bad_plants_and_stiff_springs():
    plant = MultibodyPlant(1e-3)
    arm = add_baxter_arm(plant)
    with pytest.raises(ValueError, match="detent_stiffness"):
        add_cotter_pin_scene(plant, arm, params=CotterPinParams(detent_stiffness=1e7))
    continuous = MultibodyPlant(0.0)
    with pytest.raises(ValueError, match="discrete plant"):
        add_cotter_pin_scene(continuous, add_baxter_arm(continuous))
    plant.Finalize()
    with pytest.raises(ValueError, match="before plant.Finalize"):
        add_cotter_pin_scene(plant, arm)
    with pytest.raises(ValueError, match="margin"):
        default_cotter_pin_plan(margin=-0.01)


def test_params_load_from_yaml():
    params = yaml_load_typed(
        schema=CotterPinParams, data="ring_position: [0.6, -0.8, 0.1]\nhold_force: 60.0\n"
    )
    assert params.hold_force == 60.0
    np.testing.assert_allclose(default_cotter_pin_plan(params).points[0], [0.6, -0.8, 0.1])
    # yaml_load_typed sets fields after construction: the consumers check them.
    bad = yaml_load_typed(schema=CotterPinParams, data="hold_force: .nan\n")
    with pytest.raises(ValueError, match="CotterPinParams.hold_force"):
        default_cotter_pin_plan(bad)
