"""ForceFeedback: both modes by port evaluation and in closed loop with the HapticMaster."""

import numpy as np
import pytest
from pydrake.math import RollPitchYaw, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource
from scipy.linalg import expm

from hemg_drake.teleop.config import FeedbackConfig
from hemg_drake.teleop.delay_loop import simulate_delayed_spring_loop
from hemg_drake.teleop.feedback import ForceFeedback as _ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMapping
from hemg_drake.teleop.master import HapticMaster


def ForceFeedback(*, mapping, period=1e-3, **settings):
    """The system with FeedbackConfig's defaults but ``settings``."""
    return _ForceFeedback(mapping=mapping, period=period, config=FeedbackConfig(**settings))


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


def _free_stylus_under(feedback, slave, duration):
    """Where a free stylus (no hand) is after ``duration`` s with ``feedback`` driving its
    motors from the constant slave values ``slave`` (port name -> 3 floats) and, in mode
    "position_error", from the stylus itself."""
    builder = DiagramBuilder()
    master = builder.AddSystem(HapticMaster())
    builder.AddSystem(feedback)
    for name, value in slave.items():
        builder.Connect(
            builder.AddSystem(ConstantVectorSource(value)).get_output_port(),
            feedback.GetInputPort(name),
        )
    if feedback.mode == "position_error":
        for name in ("p_MS", "v_MS"):
            builder.Connect(master.GetOutputPort(name), feedback.GetInputPort(name))
    builder.Connect(feedback.GetOutputPort("motor_force"), master.GetInputPort("motor_force"))
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(np.zeros(3))).get_output_port(),
        master.GetInputPort("hand_force"),
    )
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(duration)
    return master.GetOutputPort("p_MS").Eval(master.GetMyContextFromRoot(simulator.get_context()))


def test_force_mode_pushes_the_stylus_the_way_the_slave_is_pushed(mapping):
    f_WE = np.array([0.0, 0.0, -3.0])  # the environment pushes the slave down
    p_MS = _free_stylus_under(ForceFeedback(mapping=mapping), {"f_WE": f_WE}, 0.02)
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
    feedback = ForceFeedback(mapping=mapping, mode="position_error")
    # Table I's gains on the 45 g tip: overdamped, slow pole at about K/(K_d + b) = 1 /s.
    p_MS = _free_stylus_under(feedback, {"p_WE": p_WE, "v_WE": np.zeros(3)}, 5.0)
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


# --- delay and passivity (issue 18) -------------------------------------------------------


def test_defaults_keep_the_stateless_feedthrough(mapping):
    for mode in ("force", "position_error"):
        system = ForceFeedback(mapping=mapping, mode=mode)
        assert system.num_discrete_state_groups() == 0 and not system.stateful
    assert not ForceFeedback(mapping=mapping).HasInputPort("v_MS")
    assert ForceFeedback(mapping=mapping, passivity="tdpa").HasInputPort("v_MS")


def _step_by_step(system, inputs_at, steps):
    """motor_force at t_k = k T as the master samples it, the inputs of sample k fixed."""
    simulator = Simulator(system)
    context = simulator.get_mutable_context()
    for name, value in inputs_at(0).items():
        system.GetInputPort(name).FixValue(context, np.asarray(value, float))
    simulator.Initialize()
    forces = []
    for k in range(steps):
        simulator.AdvanceTo(k * 1e-3)  # the updates of samples 0 .. k-1 are done
        for name, value in inputs_at(k).items():
            system.GetInputPort(name).FixValue(context, np.asarray(value, float))
        forces.append(system.GetOutputPort("motor_force").Eval(context).copy())
    return np.array(forces), simulator


def test_delay_shifts_the_slave_force_by_n_samples(mapping):
    n, R = 7, mapping.R_WM.matrix()
    system = ForceFeedback(mapping=mapping, gain=0.5, delay_steps=n)

    def f_WE(k):
        return np.array([np.sin(0.3 * k), 0.1 * k, -1.0])

    forces, _ = _step_by_step(system, lambda k: {"f_WE": f_WE(k)}, 30)
    for k in range(30):
        # Before the start the slave held its first force.
        expected = 0.5 * R.T @ f_WE(max(k - n, 0)) / 3.0
        np.testing.assert_allclose(forces[k], expected, rtol=1e-12, atol=1e-15)


def test_delay_in_position_error_mode_delays_the_slave_not_the_stylus(mapping):
    n = 4
    system = ForceFeedback(mapping=mapping, mode="position_error", delay_steps=n, peak_force=1e3)

    def inputs(k):
        return dict(p_WE=[0.7 + 0.01 * k, -0.2, 0.3], v_WE=[0.0, 0.02 * k, 0.0],
                    p_MS=[0.001 * k, 0.0, 0.0], v_MS=[0.0, 0.0, 0.003 * k])  # fmt: skip

    forces, _ = _step_by_step(system, inputs, 12)
    for k in range(12):
        slave, master = inputs(max(k - n, 0)), inputs(k)
        e = mapping.slave_to_master(slave["p_WE"]) - np.array(master["p_MS"])
        edot = mapping.velocity_to_master(slave["v_WE"]) - np.array(master["v_MS"])
        np.testing.assert_allclose(forces[k], 50.0 * e + 50.0 * edot, rtol=1e-12, atol=1e-14)


def test_passivity_controller_removes_only_the_energy_the_channel_never_took(mapping):
    # A constant fed-back force F and a stylus velocity v, by hand in M: F = R^T f / 3.
    R, T = mapping.R_WM.matrix(), 1e-3
    f_WE = np.array([3.0, -1.5, 2.0])
    F = R.T @ f_WE / 3.0
    v = -F / np.linalg.norm(F) * 0.2 + np.array([0.05, 0.0, 0.0])
    assert F @ v < 0  # the stylus moves against the force: the channel absorbs energy
    absorb, flip = 10, 25

    def inputs(k):
        return {"f_WE": f_WE, "v_MS": v if k < absorb else -v}

    system = ForceFeedback(mapping=mapping, passivity="tdpa")
    forces, simulator = _step_by_step(system, inputs, flip)
    # Absorbing: the force goes through unchanged; the observer sums -T F.v per sample.
    np.testing.assert_allclose(forces[:absorb], np.tile(F, (absorb, 1)), rtol=1e-12)
    # Reversed: the stored energy lets exactly as many samples through as it took.
    np.testing.assert_allclose(forces[absorb : 2 * absorb - 1], np.tile(F, (absorb - 1, 1)),
                               rtol=1e-12)  # fmt: skip
    # Then the controller's damper cancels the force's component along v: no power out.
    projected = F - (F @ v) / (v @ v) * v
    for force in forces[2 * absorb + 1 :]:
        np.testing.assert_allclose(force, projected, rtol=1e-9, atol=1e-12)
        assert force @ -v == pytest.approx(0.0, abs=1e-12)
    context = system.GetMyContextFromRoot(simulator.get_context())
    assert system.energy(context) == pytest.approx(0.0, abs=1e-12)


def test_the_undelayed_spring_loop_is_the_sampled_spring_damper():
    # Written here from the loop's figures: per axis, the 45 g tip with 0.1 N s/m backdrive
    # damping, stepped exactly over each 1 ms sample (zero-order hold) under the force of
    # its state at the sample's start, -(300 + 500) x - 5 v: the hand's 300 N/m and 5 N s/m,
    # and the 500 N/m spring unscaled (the map doubles the motion, the feedback halves the
    # force).
    mass, backdrive, period = 0.045, 0.1, 1e-3
    A = np.array([[0.0, 1.0, 0.0], [0.0, -backdrive / mass, 1.0 / mass], [0.0, 0.0, 0.0]])
    transition = expm(A * period)
    step = transition[:2, :2] + transition[:2, 2:] @ np.array([[-800.0, -5.0]])
    x, energy = simulate_delayed_spring_loop(0, "none", duration=0.2)
    assert energy.size == 0  # no delay, no passivity controller: no state
    states = [np.array([0.005, 0.0])]
    for _ in range(250):
        states.append(step @ states[-1])
    # AdvanceTo(t) has applied the updates at k T < t (t from np.arange, as sampled).
    times = np.arange(0.01, 0.2 + 1e-9, 0.01)
    updates = [int(np.sum(np.arange(250) * period < t)) for t in times]
    expected = [abs(states[n][0]) for n in updates]
    np.testing.assert_allclose(x, expected, rtol=0.0, atol=1e-15)


def test_delayed_force_feedback_oscillates_and_the_passive_loop_settles():
    # Without delay the loop settles (the hand's damping wins); 20 ms each way, it keeps
    # oscillating by centimetres; the passivity controller makes it settle again.
    settled, _ = simulate_delayed_spring_loop(0, "none", duration=2.0)
    assert settled[-50:].max() < 1e-4
    plain, _ = simulate_delayed_spring_loop(20, "none", duration=2.0)
    assert plain[-50:].max() > 0.01
    passive, energy = simulate_delayed_spring_loop(20, "tdpa", duration=2.0)
    assert passive[-50:].max() < 1e-4
    assert energy.min() > -1e-9  # the channel never gave out more than it took


def test_passivity_without_the_stylus_velocity_is_named(mapping):
    system = ForceFeedback(mapping=mapping, passivity="tdpa")
    context = system.CreateDefaultContext()
    system.GetInputPort("f_WE").FixValue(context, np.zeros(3))
    with pytest.raises(ValueError, match="connect the master's v_MS"):
        system.GetOutputPort("motor_force").Eval(context)


# --- scalar conversion: clone, AutoDiffXd ------------------------------------------------


@pytest.mark.parametrize("mode", ["force", "position_error"])
def test_feedback_converts_to_autodiff_with_the_law_jacobian(mapping, mode):
    from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff

    system = ForceFeedback(mapping=mapping, mode=mode, gain=2.0, peak_force=1e3).ToAutoDiffXd()
    context = system.CreateDefaultContext()
    names = [system.get_input_port(i).get_name() for i in range(system.num_input_ports())]
    values = InitializeAutoDiff(np.linspace(0.01, 0.1, 3 * len(names))).ravel()
    for i, name in enumerate(names):
        system.GetInputPort(name).FixValue(context, values[3 * i : 3 * i + 3])
    jacobian = ExtractGradient(system.GetOutputPort("motor_force").Eval(context))
    RT = mapping.R_WM.matrix().T / 3.0  # scale 3
    if mode == "force":
        np.testing.assert_allclose(jacobian, 2.0 * RT, rtol=1e-14)
    else:  # [p_WE, v_WE, p_MS, v_MS]: 50 R^T / s, 50 R^T / s, -50 I, -50 I
        I = np.eye(3)
        expected = np.hstack([50.0 * RT, 50.0 * RT, -50.0 * I, -50.0 * I])
        np.testing.assert_allclose(jacobian, expected, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("delay_steps, passivity", [(0, "none"), (3, "none"), (3, "tdpa")])
def test_spring_loop_clones_and_its_autodiff_update_is_the_finite_difference(
    delay_steps, passivity
):
    # The free-space loop of the delay study (master, map, spring, feedback, delays).
    from hemg_drake.analysis.stability import (
        discrete_state as get_state,
        discrete_update_jacobian,
        set_discrete_state as set_state,
    )
    from hemg_drake.teleop.delay_loop import build_delayed_spring_loop

    diagram, _, _ = build_delayed_spring_loop(delay_steps, passivity)
    # Clone: two simulators, bit-identical states.
    states = []
    for system in (diagram, diagram.Clone()):
        simulator = Simulator(system)
        simulator.AdvanceTo(0.0505)
        states.append(get_state(simulator.get_context()))
    np.testing.assert_array_equal(states[0], states[1])
    # The AutoDiffXd loop's discrete update, differentiated at that state, against central
    # finite differences of the double loop's update (an independent differentiation).
    x0 = states[0]
    float_context = diagram.CreateDefaultContext()

    def update(x):
        set_state(float_context, x)
        values = diagram.EvalUniquePeriodicDiscreteUpdate(float_context)
        return np.concatenate([values.get_vector(i).CopyToVector()
                               for i in range(values.num_groups())])  # fmt: skip

    set_state(float_context, x0)
    jacobian = discrete_update_jacobian(diagram, float_context)
    h = 1e-7
    numeric = np.column_stack([
        (update(x0 + h * e) - update(x0 - h * e)) / (2 * h) for e in np.eye(len(x0))
    ])  # fmt: skip
    assert jacobian.shape == (len(x0), len(x0))
    np.testing.assert_allclose(jacobian, numeric, rtol=1e-5, atol=1e-5)


def test_gains_live_in_the_context(mapping):
    # One built system, two contexts: the default gains, and K_pm = 20, K_dm = 0 set in the
    # second; the force by hand in each (no saturation at a 100 N limit).
    system = ForceFeedback(mapping=mapping, mode="position_error", peak_force=100.0)
    p_WE, v_WE = np.array([0.75, -0.18, 0.33]), np.array([0.1, 0.0, -0.2])
    p_MS, v_MS = np.array([0.01, -0.02, 0.0]), np.array([0.0, 0.05, 0.01])
    e = mapping.slave_to_master(p_WE) - p_MS
    edot = mapping.velocity_to_master(v_WE) - v_MS
    forces = []
    for gains in ({}, dict(stiffness=20.0, damping=0.0)):
        context = system.CreateDefaultContext()
        system.set_gains(context, **gains)
        for name, value in (("p_WE", p_WE), ("v_WE", v_WE), ("p_MS", p_MS), ("v_MS", v_MS)):
            system.GetInputPort(name).FixValue(context, value)
        forces.append(system.GetOutputPort("motor_force").Eval(context))
    np.testing.assert_allclose(forces[0], 50.0 * e + 50.0 * edot, rtol=1e-12)
    np.testing.assert_allclose(forces[1], 20.0 * e, rtol=1e-12)
