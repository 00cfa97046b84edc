"""HsmmGmrReproducer, HsmmLqrReproducer and TrackingForce in Drake diagrams.

The comparisons with ``reproduce`` are wiring tests (it runs the same policy step offline);
the maths is pinned by references that share no code with it: eq. 18 on the system's own
outputs, the cross-track attractor pulling onto the demonstrated path, eq. 23 by hand, and
``test_reproducer_reference.py``'s closed forms.
"""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from hemg_drake.learning.reproduce import HsmmGmrPolicy, reproduce
from hemg_drake.learning.systems import HsmmGmrReproducer, HsmmLqrReproducer, TrackingForce

DT = 0.01


def run(diagram, systems, n_steps):
    """Advance to the middle of each period; read every output of ``systems``."""
    simulator = Simulator(diagram)
    root = simulator.get_mutable_context()
    rows = []
    for k in range(n_steps):
        simulator.AdvanceTo((k + 0.5) * DT)
        row = {}
        for name, system in systems.items():
            context = system.GetMyContextFromRoot(root)
            for i in range(system.num_output_ports()):
                port = system.get_output_port(i)
                row[name, port.get_name()] = port.Eval(context).copy()
        rows.append(row)
    return {key: np.array([row[key] for row in rows]) for key in rows[0]}


@pytest.mark.parametrize(
    "weighting, kappa", [("temporal", 0.0), ("spatial", 0.0), ("forward", 0.0), ("temporal", 5.0)]
)
def test_wiring_reproducer_in_a_simulator_steps_as_the_policy_does(path_task, weighting, kappa):
    # Wiring only (the system runs the same HsmmGmrPolicy): the maths is pinned by the eq. 18
    # and cross-track tests below, which fail on those mutations.
    # From 1 cm aside, so that the cross-track attractor (kappa > 0) has work to do.
    start, n_steps = path_task.mean[0, :3] + [0.0, 0.01, 0.0], 80
    builder = DiagramBuilder()
    reproducer = builder.AddSystem(
        HsmmGmrReproducer(
            model=path_task.model, start=start, dt=DT, weighting=weighting, restoring_gain=kappa
        )
    )
    builder.Connect(reproducer.GetOutputPort("x_star"), reproducer.GetInputPort("p_WE"))
    log = run(builder.Build(), {"r": reproducer}, n_steps)

    expected = reproduce(
        path_task.model, start, n_steps + 1, dt=DT, weighting=weighting, restoring_gain=kappa
    )
    # After the update at t_k the state holds step k's outputs and x*_{k+1}.
    np.testing.assert_allclose(log["r", "x_star"], expected.x[1:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(log["r", "xdot_star"], expected.xdot[:-1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(log["r", "k_star"], expected.k[:-1], rtol=1e-9)
    np.testing.assert_allclose(log["r", "h"], expected.h[:-1], rtol=0, atol=1e-9)


def test_reproducer_reads_the_measured_position(path_task):
    # An open loop: the slave "sticks" at p_WE while x* integrates on.
    start = path_task.mean[0, :3]
    p_WE = path_task.mean[100, :3]
    builder = DiagramBuilder()
    reproducer = builder.AddSystem(HsmmGmrReproducer(model=path_task.model, start=start))
    source = builder.AddSystem(ConstantVectorSource(p_WE))
    builder.Connect(source.get_output_port(), reproducer.GetInputPort("p_WE"))
    log = run(builder.Build(), {"r": reproducer}, 20)

    policy = HsmmGmrPolicy(path_task.model, weighting="forward", dt=DT)
    x_star, predicted = start, policy.forward.initial()
    for k in range(20):
        h, xdot, stiffness, x_star, predicted = policy.step(p_WE, x_star, predicted)
        np.testing.assert_allclose(log["r", "x_star"][k], x_star, atol=1e-12)
        np.testing.assert_allclose(log["r", "h"][k], h, atol=1e-12)
    # The velocity is the one learned near p_WE, not near the start.
    assert np.linalg.norm(log["r", "xdot_star"][-1] - path_task.mean[100, 3:6]) < np.linalg.norm(
        log["r", "xdot_star"][-1] - path_task.mean[0, 3:6]
    )


def distance_to_path(points, path):
    """Distance (m) of each point, shape (n, 3), to the nearest sample of ``path`` (m, 3)."""
    return np.min(np.linalg.norm(points[:, None, :] - path[None, :, :], axis=2), axis=1)


@pytest.mark.parametrize("kappa", [0.0, 5.0])
def test_eq_18_integrates_the_velocity_it_outputs(path_task, kappa):
    # x*_{k+1} = x*_k + dt xdot*_k (eq. 18), checked on the system's own outputs alone: row k
    # holds x*_{k+1} and xdot*_k (the update at k dt), x*_0 the start.
    start, n_steps = path_task.mean[0, :3] + [0.0, 0.01, 0.0], 120
    builder = DiagramBuilder()
    reproducer = builder.AddSystem(
        HsmmGmrReproducer(model=path_task.model, start=start, restoring_gain=kappa)
    )
    builder.Connect(reproducer.GetOutputPort("x_star"), reproducer.GetInputPort("p_WE"))
    log = run(builder.Build(), {"r": reproducer}, n_steps)
    x_star = np.vstack([start, log["r", "x_star"]])
    np.testing.assert_allclose(np.diff(x_star, axis=0), DT * log["r", "xdot_star"], atol=1e-15)
    # And the reference goes the demonstrated way: nearer the demonstrations' point of 1.2 s
    # than where it started.
    here = path_task.mean[n_steps, :3]
    assert np.linalg.norm(x_star[-1] - here) < 0.5 * np.linalg.norm(start - here)


def test_cross_track_attractor_pulls_back_onto_the_path(path_task):
    # From 1 cm beside the demonstrated path, kappa = 5 1/s pulls the reference back across
    # it (an offset decays as exp(-kappa t): to 1/e in 0.2 s); without it the offset stays.
    start = path_task.mean[0, :3] + [0.0, 0.01, 0.0]
    path = path_task.mean[:, :3]

    def offsets(kappa):
        builder = DiagramBuilder()
        reproducer = builder.AddSystem(
            HsmmGmrReproducer(model=path_task.model, start=start, restoring_gain=kappa)
        )
        builder.Connect(reproducer.GetOutputPort("x_star"), reproducer.GetInputPort("p_WE"))
        log = run(builder.Build(), {"r": reproducer}, 60)
        return distance_to_path(log["r", "x_star"], path)

    initial = distance_to_path(start[None, :], path)[0]
    free, pulled = offsets(0.0), offsets(5.0)
    assert initial > 0.008
    assert pulled[-1] < 0.35 * initial  # exp(-5 x 0.6) = 0.05, with the path's own slack
    assert pulled[-1] < 0.5 * free[-1]


def test_reproducers_and_tracking_force_clone_and_simulate_alike(path_task):
    # Clone() is a double -> double scalar conversion: two simulators, bit-identical logs.
    start, goal = path_task.mean[0, :3], path_task.mean[-1, :3]
    builder = DiagramBuilder()
    gmr = builder.AddNamedSystem("gmr", HsmmGmrReproducer(model=path_task.model, start=start))
    lqr = builder.AddNamedSystem(
        "lqr", HsmmLqrReproducer(model=path_task.model, start=start, weighting="temporal")
    )
    force = builder.AddNamedSystem("force", TrackingForce(kp=50.0, kd=5.0))
    goal_source = builder.AddSystem(ConstantVectorSource(goal))
    builder.Connect(gmr.GetOutputPort("x_star"), gmr.GetInputPort("p_WE"))
    builder.Connect(gmr.GetOutputPort("x_star"), lqr.GetInputPort("p_WE"))
    builder.Connect(lqr.GetOutputPort("x_star"), force.GetInputPort("x_star"))
    builder.Connect(lqr.GetOutputPort("xdot_star"), force.GetInputPort("xdot_star"))
    builder.Connect(goal_source.get_output_port(), force.GetInputPort("x_goal"))
    builder.ExportOutput(force.GetOutputPort("F_tr"), "F_tr")
    diagram = builder.Build()
    results = []
    for system in (diagram, diagram.Clone()):
        simulator = Simulator(system)
        simulator.AdvanceTo(0.305)
        results.append(system.GetOutputPort("F_tr").Eval(simulator.get_context()).copy())
    assert np.any(results[0] != 0.0)
    np.testing.assert_array_equal(results[0], results[1])


def test_tracking_force_converts_to_autodiff_with_the_eq_23_jacobian():
    from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff

    system = TrackingForce(kp=[10.0, 20.0, 30.0], kd=2.0).ToAutoDiffXd()
    context = system.CreateDefaultContext()
    values = InitializeAutoDiff(np.arange(9.0)).ravel()
    for i, name in enumerate(("x_star", "xdot_star", "x_goal")):
        system.GetInputPort(name).FixValue(context, values[3 * i : 3 * i + 3])
    jacobian = ExtractGradient(system.GetOutputPort("F_tr").Eval(context))
    K_p, K_d = np.diag([10.0, 20.0, 30.0]), 2.0 * np.eye(3)
    np.testing.assert_array_equal(jacobian, np.hstack([-K_p, K_d, K_p]))


def test_ports_and_initial_outputs(path_task):
    model = path_task.model
    start = path_task.mean[0, :3]
    reproducer = HsmmGmrReproducer(model=model, start=start)
    context = reproducer.CreateDefaultContext()
    sizes = {
        name: reproducer.GetOutputPort(name).size()
        for name in ("x_star", "xdot_star", "k_star", "h")
    }
    assert sizes == {"x_star": 3, "xdot_star": 3, "k_star": 1, "h": model.n_states}
    assert reproducer.GetInputPort("p_WE").size() == 3
    np.testing.assert_array_equal(reproducer.GetOutputPort("x_star").Eval(context), start)
    # Before the first update the stiffness is already the one learned at the start.
    first = reproduce(model, start, 1)
    np.testing.assert_allclose(reproducer.GetOutputPort("k_star").Eval(context), first.k[0])


def test_tracking_force_is_eq_23():
    system = TrackingForce(kp=[10.0, 20.0, 30.0], kd=2.0)
    context = system.CreateDefaultContext()
    system.GetInputPort("x_star").FixValue(context, [0.1, 0.2, 0.3])
    system.GetInputPort("xdot_star").FixValue(context, [1.0, -1.0, 0.5])
    system.GetInputPort("x_goal").FixValue(context, [0.5, 0.5, 0.5])
    # K_ptr (x_g - x*) + K_dtr xdot*, worked by hand.
    np.testing.assert_allclose(system.GetOutputPort("F_tr").Eval(context), [6.0, 4.0, 7.0])


def test_tracking_force_follows_the_reproducer(path_task):
    start, goal = path_task.mean[0, :3], path_task.mean[-1, :3]
    builder = DiagramBuilder()
    reproducer = builder.AddSystem(HsmmGmrReproducer(model=path_task.model, start=start))
    force = builder.AddSystem(TrackingForce(kp=50.0, kd=5.0))
    goal_source = builder.AddSystem(ConstantVectorSource(goal))
    builder.Connect(reproducer.GetOutputPort("x_star"), reproducer.GetInputPort("p_WE"))
    builder.Connect(reproducer.GetOutputPort("x_star"), force.GetInputPort("x_star"))
    builder.Connect(reproducer.GetOutputPort("xdot_star"), force.GetInputPort("xdot_star"))
    builder.Connect(goal_source.get_output_port(), force.GetInputPort("x_goal"))
    log = run(builder.Build(), {"r": reproducer, "f": force}, 30)
    expected = 50.0 * (goal - log["r", "x_star"]) + 5.0 * log["r", "xdot_star"]
    np.testing.assert_allclose(log["f", "F_tr"], expected, rtol=1e-12)


def test_bad_parameters_and_inputs_are_rejected(path_task):
    model, start = path_task.model, path_task.mean[0, :3]
    with pytest.raises(ValueError, match="kp must be finite and >= 0"):
        TrackingForce(kp=-1.0, kd=1.0)
    with pytest.raises(ValueError, match=r"kd must be a scalar or have shape \(3,\)"):
        TrackingForce(kp=1.0, kd=[1.0, 2.0])
    with pytest.raises(ValueError, match="size must be an integer >= 1"):
        TrackingForce(kp=1.0, kd=1.0, size=0)
    with pytest.raises(ValueError, match="dt must be a finite number > 0"):
        HsmmGmrReproducer(model=model, start=start, dt=np.inf)
    with pytest.raises(ValueError, match="start must have shape"):
        HsmmGmrReproducer(model=model, start=start[:2])
    with pytest.raises(ValueError, match="weighting"):
        HsmmGmrReproducer(model=model, start=start, weighting="spacial")
    with pytest.raises(ValueError, match="restoring_gain"):
        HsmmGmrReproducer(model=model, start=start, restoring_gain=-1.0)
    reproducer = HsmmGmrReproducer(model=model, start=start)
    simulator = Simulator(reproducer)
    reproducer.GetInputPort("p_WE").FixValue(simulator.get_mutable_context(), [0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="p_WE contains NaN"):
        simulator.AdvanceTo(0.5 * DT)


# ------------------------------------------------------------------- HsmmLqrReproducer
@pytest.mark.parametrize(
    "weighting, horizon, state_cost",
    [("temporal", 100, "active"), ("temporal", 100, "mixture"), ("forward", 20, "active")],
)
def test_wiring_lqr_reproducer_in_a_simulator_steps_as_the_policy_does(
    path_task, weighting, horizon, state_cost
):
    start, n_steps = path_task.mean[0, :3] + [0.0, 0.01, 0.0], 60
    builder = DiagramBuilder()
    reproducer = builder.AddSystem(
        HsmmLqrReproducer(
            model=path_task.model, start=start, dt=DT, weighting=weighting, horizon=horizon,
            state_cost=state_cost,
        )  # fmt: skip
    )
    builder.Connect(reproducer.GetOutputPort("x_star"), reproducer.GetInputPort("p_WE"))
    log = run(builder.Build(), {"r": reproducer}, n_steps)

    expected = reproduce(
        path_task.model, start, n_steps + 1, dt=DT, weighting=weighting, tracker="lqr",
        horizon=horizon, state_cost=state_cost,
    )  # fmt: skip
    # After the update at t_k the state holds h_k, k*_k and the plan's next state.
    np.testing.assert_allclose(log["r", "x_star"], expected.x[1:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(log["r", "xdot_star"], expected.xdot[1:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(log["r", "k_star"], expected.k[:-1], rtol=1e-9)
    np.testing.assert_allclose(log["r", "h"], expected.h[:-1], rtol=0, atol=1e-9)


@pytest.mark.parametrize("weighting", ["temporal", "forward"])
@pytest.mark.parametrize("max_lead", [0.0, 0.02])
def test_lqr_reference_stays_by_an_arm_held_back(path_task, weighting, max_lead):
    # The arm is stuck at the start (p_WE constant) while the task moves 13 cm on.
    start = path_task.mean[0, :3]
    n_steps = 300

    def held(reproducer):
        builder = DiagramBuilder()
        builder.AddSystem(reproducer)
        source = builder.AddSystem(ConstantVectorSource(start))
        builder.Connect(source.get_output_port(), reproducer.GetInputPort("p_WE"))
        return run(builder.Build(), {"r": reproducer}, n_steps)

    lqr_log = held(
        HsmmLqrReproducer(
            model=path_task.model, start=start, weighting=weighting, max_lead=max_lead
        )
    )
    gmr_log = held(HsmmGmrReproducer(model=path_task.model, start=start, weighting=weighting))

    x_star, xdot_star = lqr_log["r", "x_star"], lqr_log["r", "xdot_star"]
    # Eq. 18 on the stuck position runs away with the task; the re-planned reference does not.
    assert np.linalg.norm(gmr_log["r", "x_star"][-1] - start) > 0.05
    lead = np.linalg.norm(x_star - start, axis=1)
    assert np.max(lead) < max_lead + 0.01
    # Each plan starts at most max_lead from p_WE, and moves by the double integrator under
    # a constant acceleration: x*_{k+1} = x_plan + dt (xdot*_k + xdot*_{k+1}) / 2.
    previous = np.vstack([np.zeros(3), xdot_star[:-1]])
    plan = x_star - 0.5 * DT * (previous + xdot_star)
    assert np.all(np.linalg.norm(plan - start, axis=1) <= max_lead + 1e-12)
    if max_lead > 0:
        assert np.max(lead) > 0.5 * max_lead  # the plan leads the held arm, to pull it
    # The weights observe the measured p_WE, not the plan: as eqs. 12-13 do for HsmmGmr.
    np.testing.assert_allclose(lqr_log["r", "h"], gmr_log["r", "h"], rtol=0, atol=1e-12)


def test_lqr_reproducer_ports_and_initial_outputs(path_task):
    model, start = path_task.model, path_task.mean[0, :3]
    reproducer = HsmmLqrReproducer(model=model, start=start, weighting="temporal")
    context = reproducer.CreateDefaultContext()
    sizes = {
        name: reproducer.GetOutputPort(name).size()
        for name in ("x_star", "xdot_star", "k_star", "h")
    }
    assert sizes == {"x_star": 3, "xdot_star": 3, "k_star": 1, "h": model.n_states}
    assert reproducer.GetInputPort("p_WE").size() == 3
    np.testing.assert_array_equal(reproducer.GetOutputPort("x_star").Eval(context), start)
    np.testing.assert_array_equal(reproducer.GetOutputPort("xdot_star").Eval(context), 0.0)
    first = reproduce(model, start, 1, weighting="temporal", tracker="lqr")
    np.testing.assert_allclose(reproducer.GetOutputPort("k_star").Eval(context), first.k[0])
    np.testing.assert_allclose(reproducer.GetOutputPort("h").Eval(context), first.h[0])


def test_lqr_reproducer_rejects_bad_parameters_and_inputs(path_task):
    model, start = path_task.model, path_task.mean[0, :3]
    with pytest.raises(ValueError, match="weighting must be one of .* with tracker='lqr'"):
        HsmmLqrReproducer(model=model, start=start, weighting="spatial")
    with pytest.raises(ValueError, match="horizon must be an integer >= 1"):
        HsmmLqrReproducer(model=model, start=start, horizon=2.5)
    with pytest.raises(ValueError, match="control_cost must be a finite number > 0"):
        HsmmLqrReproducer(model=model, start=start, control_cost=np.nan)
    with pytest.raises(ValueError, match="dt must be a finite number > 0"):
        HsmmLqrReproducer(model=model, start=start, dt=0.0)
    with pytest.raises(ValueError, match=r"max_lead must be a finite number >= 0 \(m\)"):
        HsmmLqrReproducer(model=model, start=start, max_lead=-0.01)
    with pytest.raises(ValueError, match="state_cost must be one of"):
        HsmmLqrReproducer(model=model, start=start, state_cost="all")
    with pytest.raises(ValueError, match="start must have shape"):
        HsmmLqrReproducer(model=model, start=start[:2])
    reproducer = HsmmLqrReproducer(model=model, start=start, weighting="temporal")
    simulator = Simulator(reproducer)
    reproducer.GetInputPort("p_WE").FixValue(simulator.get_mutable_context(), [np.inf, 0.0, 0.0])
    with pytest.raises(ValueError, match="p_WE contains NaN or inf"):
        simulator.AdvanceTo(0.5 * DT)
