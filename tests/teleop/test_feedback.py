"""ForceFeedback: both modes by port evaluation and in closed loop with the HapticMaster."""

import numpy as np
import pytest
from pydrake.math import RollPitchYaw, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from hemg_drake.teleop.feedback import ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMapping
from hemg_drake.teleop.master import HapticMaster


@pytest.fixture
def mapping():
    return WorkspaceMapping(
        scale=3.0, R_WM=RotationMatrix(RollPitchYaw(0.4, 0.2, -1.1)), p_WMo=[0.7, -0.2, 0.3]
    )


def motor_force(system, **inputs):
    context = system.CreateDefaultContext()
    for name, value in inputs.items():
        system.GetInputPort(name).FixValue(context, np.asarray(value, float))
    return system.GetOutputPort("motor_force").Eval(context)


def test_force_mode_rotates_scales_and_saturates(mapping):
    R = mapping.R_WM.matrix()
    feedback = ForceFeedback(mapping=mapping, gain=2.0)
    f_WE = np.array([1.5, -2.0, 0.5])
    np.testing.assert_allclose(motor_force(feedback, f_WE=f_WE), 2.0 * R.T @ f_WE / 3.0)
    large = np.array([60.0, -30.0, 20.0])
    saturated = motor_force(feedback, f_WE=large)
    assert np.linalg.norm(saturated) == pytest.approx(7.9)
    direction = R.T @ large
    np.testing.assert_allclose(saturated / 7.9, direction / np.linalg.norm(direction))


def test_force_mode_pushes_the_stylus_the_way_the_slave_is_pushed(mapping):
    builder = DiagramBuilder()
    master = builder.AddSystem(HapticMaster())
    feedback = builder.AddSystem(ForceFeedback(mapping=mapping))
    f_WE = np.array([0.0, 0.0, -3.0])  # the environment pushes the slave down
    source = builder.AddSystem(ConstantVectorSource(f_WE))
    builder.Connect(source.get_output_port(), feedback.GetInputPort("f_WE"))
    builder.Connect(feedback.GetOutputPort("motor_force"), master.GetInputPort("motor_force"))
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(np.zeros(3))).get_output_port(),
        master.GetInputPort("hand_force"),
    )
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.02)
    p_MS = master.GetOutputPort("p_MS").Eval(master.GetMyContextFromRoot(simulator.get_context()))
    # The stylus moves so that its mapped image moves down in W, in the direction of f_WE.
    moved_W = mapping.velocity_to_slave(p_MS)
    assert np.dot(moved_W, f_WE) / (np.linalg.norm(moved_W) * 3.0) > 0.999


def test_both_modes_by_hand_with_the_default_rotation():
    # Operator behind the robot: x_M = -y_W, y_M = z_W, z_M = -x_W; scale 2.
    mapping = WorkspaceMapping(scale=2.0, p_WMo=[0.7, -0.3, 0.2])
    # Force mode, gain 1.5: f_W = [3, -1, 2] -> R^T f_W = [1, 2, -3] -> x 1.5 / 2.
    feedback = ForceFeedback(mapping=mapping, gain=1.5)
    np.testing.assert_allclose(
        motor_force(feedback, f_WE=[3.0, -1.0, 2.0]), [0.75, 1.5, -2.25], rtol=1e-15
    )
    # Position error, K_pm = K_dm = 50: the slave at p_WMo + [-0.04, -0.04, 0.06] maps to
    # p_MSdes = [0.04, 0.06, 0.04] / 2, so e = [0.02, 0.03, 0.02] - p_MS = [0.01, 0.01, -0.01];
    # v_WE = [0.1, 0.2, -0.1] maps to [-0.2, -0.1, -0.1] / 2, so edot = [0, -0.05, 0.02].
    feedback = ForceFeedback(mapping=mapping, mode="position_error")
    force = motor_force(
        feedback,
        p_WE=[0.66, -0.34, 0.26],
        v_WE=[0.1, 0.2, -0.1],
        p_MS=[0.01, 0.02, 0.03],
        v_MS=[-0.1, 0.0, -0.07],
    )
    np.testing.assert_allclose(force, [0.5, -2.0, 0.5], rtol=1e-12, atol=1e-14)
    # Beyond 7.9 N: saturated in norm, direction kept (0.4 m off along -y_W: 10 N along x_M).
    far = motor_force(
        feedback, p_WE=[0.7, -0.7, 0.2], v_WE=np.zeros(3), p_MS=np.zeros(3), v_MS=np.zeros(3)
    )
    np.testing.assert_allclose(far, [7.9, 0.0, 0.0], rtol=1e-12, atol=1e-14)


def test_position_error_mode_is_the_table_one_pd(mapping):
    feedback = ForceFeedback(mapping=mapping, mode="position_error", peak_force=1e3)
    p_WE, v_WE = np.array([0.75, -0.18, 0.33]), np.array([0.1, 0.0, -0.2])
    p_MS, v_MS = np.array([0.01, -0.02, 0.0]), np.array([0.0, 0.05, 0.01])
    expected = 50.0 * (mapping.slave_to_master(p_WE) - p_MS) + 50.0 * (
        mapping.velocity_to_master(v_WE) - v_MS
    )
    force = motor_force(feedback, p_WE=p_WE, v_WE=v_WE, p_MS=p_MS, v_MS=v_MS)
    np.testing.assert_allclose(force, expected)
    assert motor_force(
        feedback, p_WE=mapping.master_to_slave(p_MS), v_WE=np.zeros(3), p_MS=p_MS, v_MS=np.zeros(3)
    ) == pytest.approx(np.zeros(3))


def test_position_error_mode_pulls_the_stylus_onto_a_still_slave(mapping):
    p_WE = mapping.master_to_slave(np.array([0.02, -0.01, 0.015]))
    builder = DiagramBuilder()
    master = builder.AddSystem(HapticMaster())
    feedback = builder.AddSystem(ForceFeedback(mapping=mapping, mode="position_error"))
    for name, value in (("p_WE", p_WE), ("v_WE", np.zeros(3))):
        builder.Connect(
            builder.AddSystem(ConstantVectorSource(value)).get_output_port(),
            feedback.GetInputPort(name),
        )
    for name in ("p_MS", "v_MS"):
        builder.Connect(master.GetOutputPort(name), feedback.GetInputPort(name))
    builder.Connect(feedback.GetOutputPort("motor_force"), master.GetInputPort("motor_force"))
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(np.zeros(3))).get_output_port(),
        master.GetInputPort("hand_force"),
    )
    simulator = Simulator(builder.Build())
    # Table I's gains on the 45 g tip: overdamped, slow pole at about K/(K_d + b) = 1 /s.
    simulator.AdvanceTo(5.0)
    p_MS = master.GetOutputPort("p_MS").Eval(master.GetMyContextFromRoot(simulator.get_context()))
    error = np.linalg.norm(p_MS - mapping.slave_to_master(p_WE))
    assert error < 0.01 * np.linalg.norm(mapping.slave_to_master(p_WE))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(mode="torque"), "mode"),
        (dict(gain=-1.0), "gain"),
        (dict(stiffness=float("nan")), "stiffness"),
        (dict(mapping="identity"), "mapping"),
    ],
)
def test_bad_parameters_are_named(mapping, kwargs, message):
    with pytest.raises(ValueError, match=message):
        ForceFeedback(**{"mapping": mapping, **kwargs})


def test_nan_force_is_rejected(mapping):
    with pytest.raises(ValueError, match="f_WE"):
        motor_force(ForceFeedback(mapping=mapping), f_WE=[0.0, np.nan, 0.0])
    system = ForceFeedback(mapping=mapping, mode="position_error")
    finite = dict(p_WE=[0.7, -0.2, 0.3], v_WE=np.zeros(3), p_MS=np.zeros(3), v_MS=np.zeros(3))
    for name in finite:
        with pytest.raises(ValueError, match=f"{name} must be finite"):
            motor_force(system, **{**finite, name: [0.0, 0.0, np.nan]})
