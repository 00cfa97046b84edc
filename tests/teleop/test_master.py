"""HapticMaster: exact mass-damper steps, motor saturation, soft walls, friction, errors.

The references are closed forms written here (the mass-damper, with Coulomb friction, the
damped spring of a wall, and the zero-order-hold matrices that Drake's Linearize must find).
"""


import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff

from hemg_drake.teleop.config import MasterConfig
from hemg_drake.teleop.master import HapticMaster

PERIOD = 1e-3


def make_master(p_MS_initial=(0.0, 0.0, 0.0), **settings):
    """A HapticMaster with MasterConfig's defaults but ``settings``."""
    return HapticMaster(config=MasterConfig(**settings), p_MS_initial=p_MS_initial)


def run_master(hand_force, motor_force=(0.0, 0.0, 0.0), duration=0.1, **parameters):
    """Simulate a HapticMaster under constant forces; return sample times and p_MS, v_MS."""
    builder = DiagramBuilder()
    master = builder.AddSystem(make_master(**parameters))
    hand = builder.AddSystem(ConstantVectorSource(np.asarray(hand_force, float)))
    motor = builder.AddSystem(ConstantVectorSource(np.asarray(motor_force, float)))
    builder.Connect(hand.get_output_port(), master.GetInputPort("hand_force"))
    builder.Connect(motor.get_output_port(), master.GetInputPort("motor_force"))
    p_log = LogVectorOutput(master.GetOutputPort("p_MS"), builder, publish_period=PERIOD)
    v_log = LogVectorOutput(master.GetOutputPort("v_MS"), builder, publish_period=PERIOD)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(duration)
    context = simulator.get_context()
    p = p_log.FindLog(context)
    return p.sample_times(), p.data().T, v_log.FindLog(context).data().T


def test_step_force_matches_analytic_mass_damper():
    mass, damping = 0.045, 2.0
    force = np.array([0.1, -0.05, 0.08])
    times, p, v = run_master(force, mass=mass, damping=damping, duration=0.1)
    tau = mass / damping
    decay = np.exp(-times / tau)[:, None]
    p_expected = force / damping * (times[:, None] - tau * (1.0 - decay))
    v_expected = force / damping * (1.0 - decay)
    assert np.max(np.abs(p_expected)) > 2e-3  # the tip really moved
    np.testing.assert_allclose(p, p_expected, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(v, v_expected, rtol=1e-9, atol=1e-14)


def test_friction_and_saturated_motor_match_the_analytic_slide():
    # From rest under a constant net force F (hand + motor saturated in norm), the velocity
    # stays along F, so Coulomb friction is -f_c F/|F| all along: the tip is a mass-damper
    # pushed by (|F| - f_c) along F. Closed form, with tau = m / b.
    mass, damping, friction, peak = 0.045, 0.3, 0.06, 0.1
    hand = np.array([0.2, 0.03, -0.1])
    motor = np.array([0.0, 0.3, 0.4])  # 0.5 N, saturated in norm to 0.1 N: [0, 0.06, 0.08]
    total = hand + np.array([0.0, 0.06, 0.08])
    times, p, v = run_master(
        hand, motor, duration=0.05, friction=friction, damping=damping, peak_force=peak
    )
    net = np.linalg.norm(total) - friction
    direction = total / np.linalg.norm(total)
    tau = mass / damping
    decay = np.exp(-times / tau)[:, None]
    p_expected = net / damping * (times[:, None] - tau * (1.0 - decay)) * direction
    v_expected = net / damping * (1.0 - decay) * direction
    assert np.linalg.norm(p_expected[-1]) > 2e-3
    np.testing.assert_allclose(p, p_expected, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(v, v_expected, rtol=1e-9, atol=1e-14)


def test_friction_stops_a_coasting_tip_where_the_analytic_solution_does():
    # m v' = -b v - f_c while v > 0: v(t) = (v0 + f_c/b) exp(-t/tau) - f_c/b, which reaches
    # zero at t_stop = tau ln(1 + b v0 / f_c); then the tip sticks.
    mass, damping, friction, v0 = 0.045, 0.3, 0.06, 0.02
    builder = DiagramBuilder()
    master = builder.AddSystem(make_master(friction=friction, damping=damping))
    zero = builder.AddSystem(ConstantVectorSource(np.zeros(3)))
    builder.Connect(zero.get_output_port(), master.GetInputPort("hand_force"))
    builder.Connect(zero.get_output_port(), master.GetInputPort("motor_force"))
    p_log = LogVectorOutput(master.GetOutputPort("p_MS"), builder, publish_period=PERIOD)
    v_log = LogVectorOutput(master.GetOutputPort("v_MS"), builder, publish_period=PERIOD)
    simulator = Simulator(builder.Build())
    context = master.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    context.get_mutable_discrete_state(1).SetFromVector([v0, 0.0, 0.0])  # group 1: v_MS
    simulator.AdvanceTo(0.05)
    times = p_log.FindLog(simulator.get_context()).sample_times()
    p = p_log.FindLog(simulator.get_context()).data()[0]
    v = v_log.FindLog(simulator.get_context()).data()[0]
    tau = mass / damping
    t_stop = tau * np.log(1.0 + damping * v0 / friction)
    sliding = times <= t_stop
    v_expected = (v0 + friction / damping) * np.exp(-times / tau) - friction / damping
    p_expected = (v0 + friction / damping) * tau * (1.0 - np.exp(-times / tau)) - (
        friction / damping
    ) * times
    assert 10 <= np.count_nonzero(sliding) < len(times) - 10
    np.testing.assert_allclose(v[sliding], v_expected[sliding], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(p[sliding], p_expected[sliding], rtol=1e-9, atol=1e-15)
    # Stopped within the sample that holds t_stop, and stuck since.
    p_stop = (v0 + friction / damping) * tau * (1.0 - np.exp(-t_stop / tau)) - (
        friction / damping
    ) * t_stop
    np.testing.assert_allclose(v[~sliding], 0.0, atol=1e-15)
    assert np.ptp(p[~sliding]) < 1e-15
    assert p_stop <= p[-1] < p_stop + v_expected[sliding][-1] * PERIOD


def test_wall_push_with_saturated_motor_is_the_analytic_damped_spring():
    # Beyond the +x wall: m x'' + (b + c) x' + k (x - x_wall) = F, F = 2.1 N of hand plus a
    # 20 N motor command saturated to 7.9 N. Underdamped (zeta = 20.1 / (2 sqrt(k m)) = 0.67)
    # about x_eq = x_wall + F / k, from rest 1 mm beyond the wall: never back inside it.
    mass, damping, k, c = 0.045, 0.1, 5000.0, 20.0
    wall = 0.08
    x0 = wall + 1e-3
    times, p, v = run_master(
        [2.1, 0.0, 0.0], [20.0, 0.0, 0.0], duration=0.1, p_MS_initial=[x0, 0.0, 0.0]
    )
    force = 2.1 + 7.9
    omega = np.sqrt(k / mass)
    zeta = (damping + c) / (2.0 * np.sqrt(k * mass))
    omega_d = omega * np.sqrt(1.0 - zeta**2)
    x_eq = wall + force / k
    e0 = x0 - x_eq
    envelope = np.exp(-zeta * omega * times)
    cos, sin = np.cos(omega_d * times), np.sin(omega_d * times)
    x_expected = x_eq + envelope * (e0 * cos + zeta * omega * e0 / omega_d * sin)
    v_expected = -envelope * e0 * omega / np.sqrt(1.0 - zeta**2) * sin
    assert zeta == pytest.approx(0.67, abs=0.01)
    assert np.all(p[:, 0] > wall)  # the wall mode throughout
    assert np.ptp(x_expected) > 1e-3
    np.testing.assert_allclose(p[:, 0], x_expected, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(v[:, 0], v_expected, rtol=1e-8, atol=1e-12)
    np.testing.assert_array_equal(p[:, 1:], 0.0)


@pytest.mark.parametrize("p_x", [0.0, 0.081])
def test_autodiff_update_is_the_zero_order_hold_of_the_mass_damper(p_x):
    # The AutoDiffXd master's discrete update, differentiated with respect to [p; v; F_hand;
    # F_motor] (what a linearisation of the loop reads): in free space each axis is
    # A_d = [[1, tau (1 - e)], [0, e]], B_d = [(T - tau (1 - e)) / b, (1 - e) / b] for both
    # inputs, e = exp(-T / tau), tau = m / b. Beyond the +x wall (p_x = 81 mm) that axis is
    # the damped spring: A_d = expm(A T) of [[0, 1], [-k/m, -(b + c)/m]] (its series here).
    mass, damping, k, c = 0.045, 0.1, 5000.0, 20.0
    master = make_master(p_MS_initial=[p_x, 0.0, 0.0]).ToAutoDiffXd()
    context = master.CreateDefaultContext()
    point = InitializeAutoDiff(np.concatenate([[p_x], np.zeros(11)])).ravel()
    context.SetDiscreteState(0, point[0:3])
    context.SetDiscreteState(1, point[3:6])
    master.GetInputPort("hand_force").FixValue(context, point[6:9])
    master.GetInputPort("motor_force").FixValue(context, point[9:12])
    update = master.EvalUniquePeriodicDiscreteUpdate(context)
    jacobian = ExtractGradient(np.concatenate([update.value(0), update.value(1)]))
    A, B = jacobian[:, :6], jacobian[:, 6:]
    tau = mass / damping
    e = np.exp(-PERIOD / tau)
    A_free = np.array([[1.0, tau * (1.0 - e)], [0.0, e]])
    B_free = np.array([(PERIOD - tau * (1.0 - e)) / damping, (1.0 - e) / damping])
    for axis in range(3):
        rows = [axis, 3 + axis]
        block = A[np.ix_(rows, rows)]
        if axis == 0 and p_x > 0.08:
            M = np.array([[0.0, 1.0], [-k / mass, -(damping + c) / mass]]) * PERIOD
            term, expected = np.eye(2), np.eye(2)
            for n in range(1, 30):
                term = term @ M / n
                expected = expected + term
            np.testing.assert_allclose(block, expected, rtol=1e-9, atol=1e-12)
            continue
        np.testing.assert_allclose(block, A_free, rtol=1e-9, atol=1e-15)
        for j in (axis, 3 + axis):  # hand_force then motor_force columns
            np.testing.assert_allclose(B[rows, j], B_free, rtol=1e-9)


def test_master_clones_and_steps_alike():
    builder = DiagramBuilder()
    master = builder.AddSystem(make_master(friction=0.06, damping=0.3))
    hand = builder.AddSystem(ConstantVectorSource(np.array([0.2, 0.03, -0.1])))
    builder.Connect(hand.get_output_port(), master.GetInputPort("hand_force"))
    builder.Connect(hand.get_output_port(), master.GetInputPort("motor_force"))
    builder.ExportOutput(master.GetOutputPort("state"), "state")
    diagram = builder.Build()
    states = []
    for system in (diagram, diagram.Clone()):
        simulator = Simulator(system)
        simulator.AdvanceTo(0.05)
        states.append(system.GetOutputPort("state").Eval(simulator.get_context()).copy())
    assert np.linalg.norm(states[0][:3]) > 1e-3
    np.testing.assert_array_equal(states[0], states[1])


def test_friction_holds_a_small_push_and_yields_to_a_larger_one():
    _, p_small, _ = run_master([0.05, 0.0, 0.0], friction=0.06, duration=0.2)
    assert np.all(p_small == 0.0)
    _, p_large, _ = run_master([0.1, 0.0, 0.0], friction=0.06, damping=0.0, duration=0.1)
    # Sliding: the net force 0.1 - 0.06 N accelerates 45 g uniformly.
    expected = 0.5 * (0.1 - 0.06) / 0.045 * 0.1**2
    assert p_large[-1, 0] == pytest.approx(expected, rel=0.02)


def test_motor_force_saturates_in_norm_keeping_direction():
    command = np.array([30.0, 0.0, -40.0])  # 50 N, beyond the 7.9 N peak
    saturated = command * 7.9 / 50.0
    _, p_motor, _ = run_master([0.0, 0.0, 0.0], command, duration=0.01)
    _, p_hand, _ = run_master(saturated, duration=0.01)
    np.testing.assert_allclose(p_motor, p_hand, rtol=1e-12, atol=1e-15)
    _, p_over, _ = run_master(command, duration=0.01)
    assert np.linalg.norm(p_over[-1]) > 5 * np.linalg.norm(p_motor[-1])
    # A command within the limit passes unchanged.
    small = np.array([0.5, -0.2, 0.1])
    _, p_small_motor, _ = run_master([0, 0, 0], small, duration=0.01)
    _, p_small_hand, _ = run_master(small, duration=0.01)
    np.testing.assert_allclose(p_small_motor, p_small_hand, rtol=1e-12)


@pytest.mark.parametrize("axis, sign", [(0, 1.0), (1, -1.0), (2, 1.0)])
def test_soft_walls_hold_a_large_push(axis, sign):
    force = np.zeros(3)
    force[axis] = sign * 10.0
    wall = 0.5 * np.array([0.16, 0.12, 0.12])[axis]
    p_touching = np.zeros(3)
    p_touching[axis] = sign * wall
    _, p, _ = run_master(force, duration=0.5, p_MS_initial=p_touching)
    depth = sign * p[:, axis] - wall
    assert depth[-1] > 0.0  # the push does reach the wall
    assert np.max(depth) < 3e-3  # and the wall holds it within a few mm
    assert depth[-1] == pytest.approx(10.0 / 5000.0, rel=0.01)  # static spring deflection


def test_zero_force_from_rest_stays_at_rest():
    p0 = np.array([0.01, -0.02, 0.03])
    _, p, v = run_master([0.0, 0.0, 0.0], duration=0.2, p_MS_initial=p0)
    assert np.all(p == p0)
    assert np.all(v == 0.0)


def test_state_port_is_position_then_velocity():
    master = make_master(p_MS_initial=[0.01, 0.02, 0.03])
    context = master.CreateDefaultContext()
    state = master.GetOutputPort("state").Eval(context)
    np.testing.assert_array_equal(state, [0.01, 0.02, 0.03, 0, 0, 0])


@pytest.mark.parametrize(
    "parameters, message",
    [
        (dict(mass=0.0), "mass"),
        (dict(damping=-1.0), "damping"),
        (dict(workspace_size=[0.1, 0.1]), "workspace_size"),
        (dict(workspace_size=[0.1, 0.0, 0.1]), "workspace_size"),
        (dict(period=float("nan")), "period"),
        (dict(p_MS_initial=[0, 0, np.inf]), "p_MS_initial"),
    ],
)
def test_bad_parameters_are_named(parameters, message):
    with pytest.raises(ValueError, match=message):
        make_master(**parameters)


def test_nan_input_is_rejected():
    with pytest.raises(ValueError, match="hand_force"):
        run_master([np.nan, 0.0, 0.0], duration=0.01)
    with pytest.raises(ValueError, match="motor_force must be finite"):
        run_master([0.0, 0.0, 0.0], motor_force=[0.0, np.inf, 0.0], duration=0.01)


def _mass_damper(force, mass, damping, t):
    """p(t), v(t) of m xddot + b xdot = force from rest at 0 (closed form)."""
    decay = np.exp(-damping * t / mass)
    v = force / damping * (1.0 - decay)
    p = force / damping * (t - mass / damping * (1.0 - decay))
    return p, v


def test_parameters_of_each_context_give_their_own_mass_damper():
    """Two contexts of one diagram, one with set_parameters (mass, damping, peak force):
    after 50 ms each tip is the closed-form mass-damper under its own force; a context's
    Clone keeps them; the AutoDiffXd system takes them with SetTimeStateAndParametersFrom."""
    builder = DiagramBuilder()
    master = builder.AddSystem(make_master())
    hand = builder.AddSystem(ConstantVectorSource(np.array([0.5, -0.2, 0.1])))
    motor = builder.AddSystem(ConstantVectorSource(np.array([1.0, 0.0, 0.0])))
    builder.Connect(hand.get_output_port(), master.GetInputPort("hand_force"))
    builder.Connect(motor.get_output_port(), master.GetInputPort("motor_force"))
    diagram = builder.Build()
    contexts = [diagram.CreateDefaultContext() for _ in range(2)]
    # An update evaluated before the change: the discretisation it caches must follow.
    master.EvalUniquePeriodicDiscreteUpdate(master.GetMyContextFromRoot(contexts[1]))
    master.set_parameters(
        master.GetMyMutableContextFromRoot(contexts[1]), mass=0.1, damping=0.5, peak_force=0.4
    )
    assert master.get_parameters(master.GetMyContextFromRoot(contexts[1])) == {
        "mass": 0.1, "damping": 0.5, "friction": 0.0, "peak_force": 0.4,
        "wall_stiffness": 5000.0, "wall_damping": 20.0,
    }  # fmt: skip
    clone = contexts[1].Clone()
    # Default: m 0.045 kg, b 0.1 N s/m, the 1 N motor below the 7.9 N peak; context 1: the
    # motor saturated at 0.4 N. The tip stays inside the box (no wall).
    forces = [np.array([1.5, -0.2, 0.1]), np.array([0.9, -0.2, 0.1])]
    for context, force, (mass, damping) in zip(
        (*contexts, clone), (*forces, forces[1]), ((0.045, 0.1), (0.1, 0.5), (0.1, 0.5))
    ):
        Simulator(diagram, context).AdvanceTo(0.05 - 0.5 * PERIOD)  # 50 samples
        p, v = _mass_damper(force, mass, damping, 0.05)
        own = master.GetMyContextFromRoot(context)
        np.testing.assert_allclose(master.GetOutputPort("p_MS").Eval(own), p, rtol=1e-9)
        np.testing.assert_allclose(master.GetOutputPort("v_MS").Eval(own), v, rtol=1e-9)
    assert np.all(np.abs(master.GetOutputPort("p_MS").Eval(master.GetMyContextFromRoot(
        contexts[0])) - master.GetOutputPort("p_MS").Eval(master.GetMyContextFromRoot(
        contexts[1]))) > 1e-5)  # fmt: skip

    master_ad = master.ToAutoDiffXd()
    context_ad = master_ad.CreateDefaultContext()
    context_ad.SetTimeStateAndParametersFrom(master.GetMyContextFromRoot(contexts[1]))
    assert master_ad.get_parameters(context_ad)["mass"] == 0.1
    p_ad = [x.value() for x in master_ad.GetOutputPort("p_MS").Eval(context_ad)]
    np.testing.assert_array_equal(
        p_ad, master.GetOutputPort("p_MS").Eval(master.GetMyContextFromRoot(contexts[1]))
    )


@pytest.mark.parametrize(
    "values, message", [({"mass": 0.0}, "mass"), ({"damping": -1.0}, "damping"),
                        ({"period": 1e-3}, "unknown master parameter")],
)  # fmt: skip
def test_bad_master_parameters_are_named(values, message):
    master = make_master()
    with pytest.raises(ValueError, match=message):
        master.set_parameters(master.CreateDefaultContext(), **values)
