"""WorkspaceMapping and WorkspaceMap: round trips, stated rotation/scale, exact delay."""

import numpy as np
import pytest
from pydrake.math import RollPitchYaw, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    DiscreteTimeDelay,
    LogVectorOutput,
    Sine,
)

from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff

from hemg_drake.teleop.config import MappingConfig, MasterConfig
from hemg_drake.teleop.mapping import WorkspaceMap, WorkspaceMapping
from hemg_drake.teleop.master import HapticMaster

PERIOD = 1e-3


def make_map(mapping, delay_steps=0, p_MS_initial=(0.0, 0.0, 0.0)):
    return WorkspaceMap(
        mapping=mapping, period=PERIOD, p_MS_initial=p_MS_initial,
        config=MappingConfig(delay_steps=delay_steps),
    )  # fmt: skip


@pytest.fixture
def mapping():
    return WorkspaceMapping(
        scale=2.5,
        R_WM=RotationMatrix(RollPitchYaw(0.3, -0.7, 1.9)),
        p_WMo=[0.6, -0.2, 0.35],
    )


def test_round_trips_are_identity(mapping):
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.08, 0.08, size=(20, 3))
    np.testing.assert_allclose(
        mapping.slave_to_master(mapping.master_to_slave(points)), points, atol=1e-15
    )
    np.testing.assert_allclose(
        mapping.velocity_to_master(mapping.velocity_to_slave(points)), points, atol=1e-15
    )
    np.testing.assert_allclose(
        mapping.force_to_slave(mapping.force_to_master(points)), points, atol=1e-15
    )
    # One vector in, one vector out.
    assert mapping.master_to_slave(points[0]).shape == (3,)


def test_default_rotation_puts_operator_behind_robot():
    mapping = WorkspaceMapping(scale=2.0, p_WMo=[0.7, -0.3, 0.2])
    np.testing.assert_allclose(mapping.master_to_slave([0.01, 0, 0]), [0.7, -0.32, 0.2])  # right
    np.testing.assert_allclose(mapping.master_to_slave([0, 0.01, 0]), [0.7, -0.3, 0.22])  # up
    np.testing.assert_allclose(mapping.master_to_slave([0, 0, 0.01]), [0.68, -0.3, 0.2])  # back
    np.testing.assert_array_equal(mapping.velocity_to_slave([0, 0.1, 0]), [0, 0, 0.2])


def test_scale_and_rotation_act_as_stated(mapping):
    R = mapping.R_WM.matrix()
    p_MS = np.array([0.01, -0.02, 0.03])
    np.testing.assert_allclose(mapping.master_to_slave(p_MS), mapping.p_WMo + 2.5 * R @ p_MS)
    # Distances scale by `scale`; forces come back rotated and divided by it.
    a, b = np.array([0.01, 0, 0]), np.array([0, 0.02, -0.01])
    distance_W = np.linalg.norm(mapping.master_to_slave(a) - mapping.master_to_slave(b))
    assert distance_W == pytest.approx(2.5 * np.linalg.norm(a - b))
    f_W = np.array([3.0, -1.0, 2.0])
    np.testing.assert_allclose(mapping.force_to_master(f_W), R.T @ f_W / 2.5)


@pytest.mark.parametrize("delay_steps", [0, 3])
def test_system_outputs_by_hand_with_the_default_rotation(delay_steps):
    # Operator behind the robot, scale 2: p_WE = p_WMo + 2 [-z_M, -x_M, y_M].
    mapping = WorkspaceMapping(scale=2.0, p_WMo=[0.7, -0.3, 0.2])
    p_initial = [0.005, -0.01, 0.02]
    system = make_map(mapping, delay_steps, p_initial)
    simulator = Simulator(system)
    context = simulator.get_mutable_context()
    system.GetInputPort("p_MS").FixValue(context, [0.01, 0.02, 0.03])
    system.GetInputPort("v_MS").FixValue(context, [0.1, -0.2, 0.05])
    p_WE, v_WE = system.GetOutputPort("p_WE_desired"), system.GetOutputPort("v_WE_desired")
    if delay_steps:
        # Until the n-th sample (at t = (n - 1) period): p_MS_initial at rest, mapped.
        simulator.AdvanceTo((delay_steps - 1.5) * PERIOD)
        np.testing.assert_allclose(p_WE.Eval(context), [0.66, -0.31, 0.18], rtol=1e-14)
        np.testing.assert_array_equal(v_WE.Eval(context), np.zeros(3))
        simulator.AdvanceTo((delay_steps - 0.5) * PERIOD)
    np.testing.assert_allclose(p_WE.Eval(context), [0.64, -0.32, 0.24], rtol=1e-14)
    np.testing.assert_allclose(v_WE.Eval(context), [-0.1, -0.2, -0.4], rtol=1e-14)


def test_system_without_delay_is_the_mapping(mapping):
    system = make_map(mapping)
    context = system.CreateDefaultContext()
    p_MS, v_MS = np.array([0.02, 0.01, -0.03]), np.array([0.1, -0.2, 0.05])
    system.GetInputPort("p_MS").FixValue(context, p_MS)
    system.GetInputPort("v_MS").FixValue(context, v_MS)
    np.testing.assert_allclose(
        system.GetOutputPort("p_WE_desired").Eval(context), mapping.master_to_slave(p_MS)
    )
    np.testing.assert_allclose(
        system.GetOutputPort("v_WE_desired").Eval(context), mapping.velocity_to_slave(v_MS)
    )


def run_delayed(mapping, delay_steps):
    """A master pushed by a sinusoidal hand force, mapped with and without delay."""
    builder = DiagramBuilder()
    master = builder.AddSystem(HapticMaster(config=MasterConfig(damping=1.0)))
    hand = builder.AddSystem(
        Sine(np.full(3, 0.2), np.array([3.0, 5.0, 7.0]) * 2 * np.pi, np.zeros(3), 3)
    )
    builder.Connect(hand.get_output_port(0), master.GetInputPort("hand_force"))
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(np.zeros(3))).get_output_port(),
        master.GetInputPort("motor_force"),
    )
    logs = {}
    # Ours, Drake's own DiscreteTimeDelay followed by an undelayed map, and no delay.
    # Drake's samples its input first, which on a held input adds one period: n - 1 steps.
    delayed = builder.AddSystem(make_map(mapping, delay_steps))
    drake_delay = builder.AddSystem(DiscreteTimeDelay(PERIOD, delay_steps - 1, 3))
    after_drake_delay = builder.AddSystem(make_map(mapping))
    undelayed = builder.AddSystem(make_map(mapping))
    builder.Connect(master.GetOutputPort("p_MS"), drake_delay.get_input_port())
    builder.Connect(drake_delay.get_output_port(), after_drake_delay.GetInputPort("p_MS"))
    for system in (delayed, after_drake_delay, undelayed):
        builder.Connect(master.GetOutputPort("v_MS"), system.GetInputPort("v_MS"))
    for system in (delayed, undelayed):
        builder.Connect(master.GetOutputPort("p_MS"), system.GetInputPort("p_MS"))
    for name, system in (("ours", delayed), ("drake", after_drake_delay), ("none", undelayed)):
        logs[name] = LogVectorOutput(
            system.GetOutputPort("p_WE_desired"), builder, publish_period=PERIOD
        )
    logs["v_ours"] = LogVectorOutput(
        delayed.GetOutputPort("v_WE_desired"), builder, publish_period=PERIOD
    )
    logs["v_none"] = LogVectorOutput(
        undelayed.GetOutputPort("v_WE_desired"), builder, publish_period=PERIOD
    )
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.3)
    return {name: log.FindLog(simulator.get_context()).data().T for name, log in logs.items()}


@pytest.mark.parametrize("n", [1, 7])
def test_delay_shifts_by_exactly_n_samples(mapping, n):
    logs = run_delayed(mapping, n)
    assert np.ptp(logs["none"], axis=0).min() > 1e-3  # the signal really moves
    np.testing.assert_array_equal(logs["ours"][n:], logs["none"][:-n])
    np.testing.assert_array_equal(logs["v_ours"][n:], logs["v_none"][:-n])
    np.testing.assert_array_equal(logs["ours"][:n], np.tile(mapping.p_WMo, (n, 1)))
    np.testing.assert_allclose(logs["ours"], logs["drake"], atol=1e-15)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(scale=0.0), "scale"),
        (dict(scale=float("nan")), "scale"),
        (dict(R_WM=np.diag([1.0, 1.0, -1.0])), "R_WM"),
        (dict(R_WM=2 * np.eye(3)), "R_WM"),
        (dict(R_WM=np.eye(2)), "R_WM"),
        (dict(p_WMo=[0.0, 1.0]), "p_WMo"),
    ],
)
def test_bad_mapping_is_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        WorkspaceMapping(**kwargs)


@pytest.mark.parametrize("delay_steps", [-1, 1.5, float("nan"), float("inf"), "two", None])
def test_bad_delay_is_named(delay_steps):
    with pytest.raises(ValueError, match="delay_steps must be a non-negative integer"):
        make_map(WorkspaceMapping(), delay_steps)


def test_map_converts_to_autodiff_with_the_affine_jacobian(mapping):
    # d[p_WE; v_WE] / d[p_MS; v_MS] = scale diag(R_WM, R_WM), through Drake's AffineSystem.
    system = make_map(mapping).ToAutoDiffXd()
    context = system.CreateDefaultContext()
    values = InitializeAutoDiff(np.array([0.01, 0.02, -0.03, 0.1, 0.0, -0.2])).ravel()
    system.GetInputPort("p_MS").FixValue(context, values[:3])
    system.GetInputPort("v_MS").FixValue(context, values[3:])
    p_WE = system.GetOutputPort("p_WE_desired").Eval(context)
    v_WE = system.GetOutputPort("v_WE_desired").Eval(context)
    R = 2.5 * RotationMatrix(RollPitchYaw(0.3, -0.7, 1.9)).matrix()
    np.testing.assert_allclose(ExtractGradient(p_WE), np.hstack([R, np.zeros((3, 3))]), atol=1e-15)
    np.testing.assert_allclose(ExtractGradient(v_WE), np.hstack([np.zeros((3, 3)), R]), atol=1e-15)
    values = np.array([x.value() for x in p_WE])
    np.testing.assert_allclose(values, [0.6, -0.2, 0.35] + R @ [0.01, 0.02, -0.03], atol=1e-15)


def test_delayed_map_clones(mapping):
    system = make_map(mapping, 4, p_MS_initial=[0.01, 0.0, 0.0])
    outputs = []
    for copy in (system, system.Clone()):
        simulator = Simulator(copy)
        context = simulator.get_mutable_context()
        copy.GetInputPort("p_MS").FixValue(context, [0.02, -0.01, 0.03])
        copy.GetInputPort("v_MS").FixValue(context, [0.1, 0.2, 0.3])
        simulator.AdvanceTo(0.0105)
        outputs.append(copy.GetOutputPort("p_WE_desired").Eval(context).copy())
    np.testing.assert_array_equal(outputs[0], outputs[1])
    np.testing.assert_allclose(outputs[0], mapping.master_to_slave([0.02, -0.01, 0.03]))
