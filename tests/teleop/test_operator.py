"""SimulatedOperator with the HapticMaster: tracking, activation levels, co-contraction, seeds."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from pydrake.common import RandomGenerator

from hemg_drake.tasks.plan import TaskPlan
from hemg_drake.teleop.config import OperatorConfig
from hemg_drake.teleop.mapping import WorkspaceMapping
from hemg_drake.teleop.master import HapticMaster
from hemg_drake.teleop.operator import SimulatedOperator as _SimulatedOperator

PERIOD = 1e-3
# No variability unless a test asks for it: the operator follows the plan it is given.
STEADY = dict(timing_std=0.0, path_std=[0.0, 0.0, 0.0], effort_std=0.0)


def SimulatedOperator(*, plan, mapping, **settings):
    """The system with OperatorConfig's defaults but ``settings`` (steady by default)."""
    return _SimulatedOperator(plan=plan, mapping=mapping, config=OperatorConfig(**{**STEADY, **settings}))


MAPPING = WorkspaceMapping(scale=3.0, p_WMo=[0.7, -0.2, 0.25])
PLAN = TaskPlan(
    times=[0.0, 0.6, 1.4, 2.0],
    points=[[0.7, -0.2, 0.25], [0.75, -0.3, 0.25], [0.75, -0.3, 0.2], [0.7, -0.2, 0.25]],
    kinds=["free", "forceful", "free"],
)


def run_operator(plan=PLAN, feedback_force=(0.0, 0.0, 0.0), duration=2.0, seed=None,
                 generator=None, **operator_parameters):  # fmt: skip
    """Operator and master in closed loop; logs at every sample instant. ``seed``: the
    operator's set_seed; ``generator``: a RandomGenerator for SetRandomContext."""
    builder = DiagramBuilder()
    # The stylus starts where the task starts (the nominal plan's first point), as in a
    # demonstration; the operator's own plan may vary from there.
    master = builder.AddSystem(HapticMaster(p_MS_initial=MAPPING.slave_to_master(PLAN.points[0])))
    operator = builder.AddSystem(
        SimulatedOperator(plan=plan, mapping=MAPPING, **operator_parameters)
    )
    felt = builder.AddSystem(ConstantVectorSource(np.asarray(feedback_force, float)))
    builder.Connect(felt.get_output_port(), operator.GetInputPort("feedback_force"))
    builder.Connect(operator.GetOutputPort("hand_force"), master.GetInputPort("hand_force"))
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(np.zeros(3))).get_output_port(),
        master.GetInputPort("motor_force"),
    )
    for name in ("p_MS", "v_MS"):
        builder.Connect(master.GetOutputPort(name), operator.GetInputPort(name))
    logs = {
        "p_MS": LogVectorOutput(master.GetOutputPort("p_MS"), builder, publish_period=PERIOD),
        "activation": LogVectorOutput(
            operator.GetOutputPort("activation"), builder, publish_period=PERIOD
        ),
        "hand_force": LogVectorOutput(
            operator.GetOutputPort("hand_force"), builder, publish_period=PERIOD
        ),
    }
    diagram = builder.Build()
    simulator = Simulator(diagram)
    root = simulator.get_mutable_context()
    if generator is not None:
        diagram.SetRandomContext(root, generator)
    if seed is not None:
        operator.set_seed(operator.GetMyMutableContextFromRoot(root), seed)
    simulator.AdvanceTo(duration)
    context = simulator.get_context()
    result = {name: log.FindLog(context).data().T for name, log in logs.items()}
    result["plan"] = operator.plan(operator.GetMyContextFromRoot(context))
    result["t"] = logs["p_MS"].FindLog(context).sample_times()
    result["activation"] = result["activation"][:, 0]
    return result


@pytest.fixture(scope="module")
def nominal():
    return run_operator()


def test_stylus_follows_the_mapped_plan(nominal):
    planned = MAPPING.slave_to_master(PLAN.position(nominal["t"]))
    error = np.linalg.norm(nominal["p_MS"] - planned, axis=1)
    assert np.ptp(planned, axis=0).max() > 0.02  # the plan moves the stylus by centimetres
    assert error.max() < 1e-3  # measured 0.12 mm on the master (0.36 mm on the slave)
    assert np.linalg.norm(nominal["hand_force"], axis=1).max() < 15.0


def test_activation_is_higher_in_forceful_segments(nominal):
    t, a = nominal["t"], nominal["activation"]
    settled = 5 * 0.04  # five time constants into a segment
    free = a[(t > settled) & (t < 0.6)]
    forceful = a[(t > 0.6 + settled) & (t < 1.4)]
    assert forceful.min() > free.max() + 0.3
    # Settled levels are the documented targets (default rest 0.05, free 0.2, forceful 0.7).
    assert free[-1] == pytest.approx(0.2, abs=1e-3)
    assert forceful[-1] == pytest.approx(0.7, abs=1e-3)
    assert np.all((a >= 0.0) & (a <= 1.0))


def test_activation_is_an_exact_first_order_lag(nominal):
    # From rest (0.05) towards the free level (0.2) with tau = 40 ms, sampled exactly: at
    # each of the activation's own sample instants t_k = k period (the logger, at 1 ms,
    # sees the value of k updates there), a = 0.2 - 0.15 exp(-t_k / tau).
    period = OperatorConfig().period
    t, a = nominal["t"], nominal["activation"]
    k = np.round(t / period)
    instants = (t < 0.3) & np.isclose(t, k * period, rtol=0, atol=1e-9)
    assert np.count_nonzero(instants) >= 50
    expected = 0.2 + (0.05 - 0.2) * np.exp(-k[instants] * period / 0.04)
    np.testing.assert_allclose(a[instants], expected, atol=1e-12)


def test_hand_force_is_the_impedance_law_by_hand():
    # At t = 0.3 s, half-way through the first segment (0.6 s), minimum jerk gives
    # s = 0.5 and ds/dtau = 1.875: the plan in W is p0 + (p1 - p0) / 2 = [0.725, -0.25, 0.25]
    # moving at 1.875 / 0.6 (p1 - p0) = [0.15625, -0.3125, 0] m/s. Into M (scale 3, offset
    # p0, operator behind the robot: x_M = -y_W, y_M = z_W, z_M = -x_W), relative to p0:
    p_plan = np.array([0.05, 0.0, -0.025]) / 3.0
    v_plan = np.array([0.3125, 0.0, -0.15625]) / 3.0
    system = SimulatedOperator(plan=PLAN, mapping=MAPPING)
    context = system.CreateDefaultContext()
    context.SetTime(0.3)
    p_MS, v_MS = np.array([0.01, 0.002, -0.005]), np.array([0.05, 0.01, -0.02])
    for name, value in (("p_MS", p_MS), ("v_MS", v_MS), ("feedback_force", np.zeros(3))):
        system.GetInputPort(name).FixValue(context, value)
    expected = 300.0 * (p_plan - p_MS) + 5.0 * (v_plan - v_MS)
    assert 1.0 < np.linalg.norm(expected) < 15.0  # not saturated
    hand_force = system.GetOutputPort("hand_force").Eval(context)
    np.testing.assert_allclose(hand_force, expected, rtol=1e-12, atol=1e-15)
    # Far from the plan: the same law saturated at 15 N, pointing the same way.
    far = np.array([0.07, -0.05, 0.05])
    system.GetInputPort("p_MS").FixValue(context, far)
    system.GetInputPort("v_MS").FixValue(context, np.zeros(3))
    unsaturated = 300.0 * (p_plan - far) + 5.0 * v_plan
    np.testing.assert_allclose(
        system.GetOutputPort("hand_force").Eval(context),
        15.0 * unsaturated / np.linalg.norm(unsaturated),
        rtol=1e-12,
    )


def test_one_activation_update_by_hand():
    # At t = 0.9 s the plan is in its forceful segment (0.6 - 1.4 s, effort 1): the target
    # is 0.7 + 0.05 |f| = 0.7 + 0.05 x 2.29 (|[1, 2, 0.5]| = sqrt(5.25)); from the rest 0.05
    # one 5 ms step of the 40 ms lag gives a* + (0.05 - a*) exp(-0.125).
    system = SimulatedOperator(plan=PLAN, mapping=MAPPING)
    context = system.CreateDefaultContext()
    context.SetTime(0.9)
    felt = np.array([1.0, 2.0, 0.5])
    for name, value in (("p_MS", np.zeros(3)), ("v_MS", np.zeros(3)), ("feedback_force", felt)):
        system.GetInputPort(name).FixValue(context, value)
    update = system.EvalUniquePeriodicDiscreteUpdate(context)
    target = 0.7 + 0.05 * np.sqrt(5.25)
    expected = target + (0.05 - target) * np.exp(-0.005 / 0.04)
    # Group 0: the law's activation (the random sources' draws follow).
    assert update.get_vector(0).GetAtIndex(0) == pytest.approx(expected, abs=1e-15)
    # Far from the plan, the hand pushes at its limit, towards the plan.
    system.GetInputPort("p_MS").FixValue(context, [0.07, -0.05, 0.05])
    far = system.GetOutputPort("hand_force").Eval(context)
    assert np.linalg.norm(far) == pytest.approx(15.0)


def test_activation_rises_with_the_felt_force(nominal):
    felt = run_operator(feedback_force=[0.0, 3.0, -4.0], duration=1.2)  # 5 N felt
    n = len(felt["t"])
    gain = felt["activation"] - nominal["activation"][:n]
    assert gain[-1] == pytest.approx(0.05 * 5.0, abs=1e-3)
    assert np.all(gain >= -1e-15)
    saturated = run_operator(feedback_force=[0.0, 0.0, 30.0], duration=0.6)
    assert saturated["activation"][-1] == pytest.approx(1.0, abs=1e-3)  # clipped at full


def test_effort_scales_the_activation_above_rest():
    strong = TaskPlan(PLAN.times, PLAN.points, PLAN.kinds, effort=[1.0, 1.2, 1.0])
    t_end = 1.35
    a = run_operator(plan=strong, duration=t_end)["activation"][-1]
    assert a == pytest.approx(0.05 + 1.2 * (0.7 - 0.05), abs=1e-3)


def test_set_seed_follows_the_plan_perturbed_by_that_seed():
    # The operator perturbing in its Context (set_seed) against one given the plan perturbed
    # outside (TaskPlan.perturbed) and no variability of its own: the same run, to the bit.
    spreads = dict(timing_std=0.1, path_std=[0.002, 0.002, 0.002], effort_std=0.1)
    inside = run_operator(duration=1.0, seed=11, **spreads)
    outside = run_operator(plan=PLAN.perturbed(11, **spreads), duration=1.0)
    for name in ("p_MS", "hand_force", "activation"):
        np.testing.assert_array_equal(inside[name], outside[name])
    np.testing.assert_array_equal(inside["plan"].times, PLAN.perturbed(11, **spreads).times)
    other = run_operator(duration=1.0, seed=12, **spreads)
    assert np.abs(inside["p_MS"] - other["p_MS"]).max() > 1e-4
    assert np.abs(inside["activation"] - other["activation"]).max() > 1e-3


def test_set_random_context_draws_the_plan_from_the_generator():
    # One built diagram, several seeds: SetRandomContext(RandomGenerator(seed)).
    spreads = dict(timing_std=0.1, path_std=[0.002, 0.002, 0.002], effort_std=0.1)
    a = run_operator(duration=0.5, generator=RandomGenerator(3), **spreads)
    b = run_operator(duration=0.5, generator=RandomGenerator(3), **spreads)
    c = run_operator(duration=0.5, generator=RandomGenerator(4), **spreads)
    for name in ("p_MS", "hand_force", "activation"):
        np.testing.assert_array_equal(a[name], b[name])
    assert np.abs(a["p_MS"] - c["p_MS"]).max() > 1e-5
    assert not np.array_equal(a["plan"].times, c["plan"].times)
    # The plan varies as configured: a shift of millimetres, segment times within 50 %.
    for run in (a, c):
        offset = np.abs(run["plan"].points - PLAN.points).max()
        assert 1e-5 < offset < 0.02
        ratio = np.diff(run["plan"].times) / np.diff(PLAN.times)
        assert np.all((ratio > 0.5) & (ratio < 1.5))
    # Without variability the generator changes nothing: the nominal plan.
    steady = run_operator(duration=0.5, generator=RandomGenerator(3))
    np.testing.assert_array_equal(steady["plan"].points, PLAN.points)


def test_operator_clones():
    spreads = dict(timing_std=0.1, path_std=[0.002, 0.002, 0.002], effort_std=0.1)
    system = SimulatedOperator(plan=PLAN, mapping=MAPPING, **spreads)
    forces = []
    for copy in (system, system.Clone()):
        simulator = Simulator(copy)
        context = simulator.get_mutable_context()
        copy.SetRandomContext(context, RandomGenerator(7))
        for name in ("p_MS", "v_MS", "feedback_force"):
            copy.GetInputPort(name).FixValue(context, np.zeros(3))
        simulator.AdvanceTo(0.3)
        forces.append(copy.GetOutputPort("hand_force").Eval(context).copy())
    assert np.linalg.norm(forces[0]) > 0.1
    np.testing.assert_array_equal(forces[0], forces[1])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(plan="pull the pin"), "plan"),
        (dict(mapping=None), "mapping"),
        (dict(hand_stiffness=-300.0), "hand_stiffness"),
        (dict(forceful_activation=1.5), "forceful_activation"),
        (dict(activation_time_constant=0.0), "activation_time_constant"),
    ],
)
def test_bad_parameters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SimulatedOperator(**{"plan": PLAN, "mapping": MAPPING, **kwargs})


def test_nan_feedback_force_is_rejected():
    with pytest.raises(ValueError, match="feedback_force"):
        run_operator(feedback_force=[np.nan, 0.0, 0.0], duration=0.01)


@pytest.mark.parametrize("name", ["p_MS", "v_MS"])
def test_nan_stylus_input_is_rejected(name):
    system = SimulatedOperator(plan=PLAN, mapping=MAPPING)
    context = system.CreateDefaultContext()
    for port in ("p_MS", "v_MS", "feedback_force"):
        system.GetInputPort(port).FixValue(context, np.zeros(3))
    system.GetInputPort(name).FixValue(context, [0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match=f"{name} must be finite"):
        system.GetOutputPort("hand_force").Eval(context)


def test_monte_carlo_runs_several_seeds_of_one_built_loop():
    # MonteCarloSimulation: one built operator + master loop, a random context per sample
    # (SetRandomContext), the end time of the operator's drawn plan as the output.
    from pydrake.systems.analysis import MonteCarloSimulation

    spreads = dict(timing_std=0.1, path_std=[0.002, 0.002, 0.002], effort_std=0.1)
    builder = DiagramBuilder()
    master = builder.AddSystem(HapticMaster(p_MS_initial=MAPPING.slave_to_master(PLAN.points[0])))
    operator = builder.AddSystem(SimulatedOperator(plan=PLAN, mapping=MAPPING, **spreads))
    zero = builder.AddSystem(ConstantVectorSource(np.zeros(3)))
    builder.Connect(zero.get_output_port(), operator.GetInputPort("feedback_force"))
    builder.Connect(zero.get_output_port(), master.GetInputPort("motor_force"))
    builder.Connect(operator.GetOutputPort("hand_force"), master.GetInputPort("hand_force"))
    for name in ("p_MS", "v_MS"):
        builder.Connect(master.GetOutputPort(name), operator.GetInputPort(name))
    diagram = builder.Build()

    def end_time(system, context):
        return operator.plan(operator.GetMyContextFromRoot(context)).end_time

    def results(seed):
        runs = MonteCarloSimulation(
            make_simulator=lambda generator: Simulator(diagram), output=end_time,
            final_time=0.05, num_samples=4, generator=RandomGenerator(seed),
        )  # fmt: skip
        return [run.output for run in runs]

    first, again = results(1), results(1)
    assert first == again  # same generator seed, same draws
    assert len(set(first)) == 4  # four different plans from one diagram
    assert all(abs(t / PLAN.end_time - 1.0) < 0.3 for t in first)
