"""CLIK (eq. 21) through its contexts: clones, the AutoDiffXd conversion, and the gains and
limits as parameters of each context."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, InitializeAutoDiff
from pydrake.systems.analysis import Simulator, Simulator_

# The Baxter plant and the CLIK helpers live in test_clik (pytest imports it as a top-level
# module: the tests/ folders are not packages).
from test_clik import _ARM, Q_PEN_DOWN, finite_difference_jacobian, make_clik, p_WE, run_clik


def test_autodiff_step_slope_is_dt_gain_J_transpose():
    """The CLIK converted to AutoDiffXd: after one update, d q_d / d p_WE_desired =
    period * gain * J^T (closed form of the transpose law; J by finite differences)."""
    diagram, _, arm = make_clik(gain=20.0)
    ad = diagram.ToAutoDiffXd()
    q0 = np.array([0.2, -0.5, 0.1, 0.8, 0.0, 1.0, 0.0])
    target = p_WE(q0) + np.array([0.02, -0.01, 0.01])
    simulator = Simulator_[AutoDiffXd](ad)
    context = simulator.get_mutable_context()
    ad.GetInputPort("p_WE_desired").FixValue(context, InitializeAutoDiff(target)[:, 0])
    ad.GetInputPort("state").FixValue(
        context, [AutoDiffXd(x) for x in np.concatenate([q0, np.zeros(7)])]
    )
    simulator.AdvanceTo(0.5e-3)  # the update at t = 0
    q_d = ad.GetOutputPort("q_desired").Eval(context)
    expected = 1e-3 * 20.0 * finite_difference_jacobian(q0).T
    np.testing.assert_allclose(ExtractGradient(q_d), expected, rtol=1e-7, atol=1e-12)


@pytest.mark.parametrize("changes", [{}, {"method": "dls", "gain": 50.0}, {"orientation_gain": 10.0}])
def test_clones_run_bit_identical(changes):
    diagram, _, _ = make_clik(**changes)
    q0 = Q_PEN_DOWN
    target = p_WE(q0) + np.array([0.05, -0.03, 0.02])
    finals = []
    for system in (diagram, diagram.Clone()):
        simulator = Simulator(system)
        context = simulator.get_mutable_context()
        system.GetInputPort("p_WE_desired").FixValue(context, target)
        system.GetInputPort("state").FixValue(context, np.concatenate([q0, np.zeros(7)]))
        simulator.AdvanceTo(0.2)
        finals.append(system.GetOutputPort("q_desired").Eval(context).copy())
    np.testing.assert_array_equal(finals[0], finals[1])
    assert np.linalg.norm(finals[0] - q0) > 0.01


@pytest.mark.parametrize("changes", [{"method": "dls", "gain": 50.0}, {"orientation_gain": 10.0}])
def test_autodiff_step_slope_matches_finite_differences(changes):
    """The DLS law and the tool-axis task under AutoDiffXd: d q_d / d p_WE_desired after one
    update against central differences of the double system's update."""
    diagram, _, _ = make_clik(**changes)
    ad = diagram.ToAutoDiffXd()
    q0 = Q_PEN_DOWN + np.array([0.1, 0.0, -0.2, 0.0, 0.2, 0.2, 0.0])
    target = p_WE(q0) + np.array([0.01, -0.005, 0.004])
    simulator = Simulator_[AutoDiffXd](ad)
    context = simulator.get_mutable_context()
    ad.GetInputPort("p_WE_desired").FixValue(context, InitializeAutoDiff(target)[:, 0])
    ad.GetInputPort("state").FixValue(
        context, [AutoDiffXd(x) for x in np.concatenate([q0, np.zeros(7)])]
    )
    simulator.AdvanceTo(0.5e-3)
    slope = ExtractGradient(ad.GetOutputPort("q_desired").Eval(context))

    def q_after(p):
        return run_clik(p, q0, 0.5e-3, **changes)[0]

    h = 1e-6
    numeric = np.column_stack(
        [(q_after(target + h * u) - q_after(target - h * u)) / (2 * h) for u in np.eye(3)]
    )
    assert np.abs(slope).max() > 1e-3
    np.testing.assert_allclose(slope, numeric, rtol=1e-5, atol=1e-8)


def test_gains_and_limits_are_parameters_of_each_context():
    """Two contexts of one DLS diagram, one with set_gains and set_limits: one update of each
    is the documented step by hand (J by finite differences) with its own gain, damping and
    limits; a context's Clone keeps them; the AutoDiffXd diagram takes them with
    SetTimeStateAndParametersFrom."""
    diagram, clik, _ = make_clik(method="dls", gain=2.0, damping=0.3)
    q0 = np.array([0.2, -0.5, 0.1, 0.8, 0.0, 1.0, 0.0])
    target = p_WE(q0) + np.array([0.05, -0.03, 0.02])
    J = finite_difference_jacobian(q0)
    e = target - p_WE(q0)

    def dls(gain, damping):
        return gain * J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(3), e)

    # Context 1: K = 40 1/s, damping 0.1 m; the joint moving fastest up has its upper limit
    # 0.1 mrad above q0, and every joint's rate bound is 0.3 rad/s.
    qdot = dls(40.0, 0.1)
    k = int(np.argmax(qdot))
    q_lower, q_upper = _ARM.position_lower - 1.0, _ARM.position_upper + 1.0
    q_upper[k] = q0[k] + 1e-4
    v_max = np.full(7, 0.3)
    rates = np.minimum(np.maximum(qdot, (q_lower - q0) / 1e-3), (q_upper - q0) / 1e-3)
    assert rates[k] < qdot[k]  # the position limit stops joint k
    ratio = np.abs(rates / v_max).max()
    assert ratio > 1.0  # and the rate bound scales every joint
    expected = [q0 + 1e-3 * dls(2.0, 0.3), q0 + 1e-3 * rates / ratio]
    assert np.abs(expected[0] - expected[1]).max() > 1e-5

    contexts = [diagram.CreateDefaultContext() for _ in range(2)]
    clik_context = clik.GetMyMutableContextFromRoot(contexts[1])
    clik.set_gains(clik_context, gain=40.0, damping=0.1)
    clik.set_limits(clik_context, q_lower=q_lower, q_upper=q_upper, v_max=v_max)
    parameters = clik.get_parameters(clik_context)
    assert (parameters["gain"], parameters["damping"]) == (40.0, 0.1)
    np.testing.assert_array_equal(parameters["v_max"], v_max)
    clone = contexts[1].Clone()
    finals = []
    for context in (*contexts, clone):
        diagram.GetInputPort("p_WE_desired").FixValue(context, target)
        diagram.GetInputPort("state").FixValue(context, np.concatenate([q0, np.zeros(7)]))
        Simulator(diagram, context).AdvanceTo(0.5e-3)  # the update at t = 0
        finals.append(diagram.GetOutputPort("q_desired").Eval(context).copy())
    np.testing.assert_allclose(finals[0], expected[0], rtol=0, atol=1e-11)
    np.testing.assert_allclose(finals[1], expected[1], rtol=0, atol=1e-11)
    np.testing.assert_array_equal(finals[2], finals[1])

    ad = diagram.ToAutoDiffXd()
    context = ad.CreateDefaultContext()
    context.SetTimeStateAndParametersFrom(diagram.CreateDefaultContext())
    clik_ad = ad.GetSubsystemByName(clik.get_name())
    ad_parameters = clik_ad.get_parameters(clik_ad.GetMyContextFromRoot(context))
    assert ad_parameters["gain"].value() == 2.0  # the default, before the copy
    context.SetTimeStateAndParametersFrom(contexts[1])  # its state is after the update
    context.SetTime(0.0)
    ad.GetInputPort("p_WE_desired").FixValue(context, [AutoDiffXd(x) for x in target])
    ad.GetInputPort("state").FixValue(
        context, [AutoDiffXd(x) for x in np.concatenate([q0, np.zeros(7)])]
    )
    Simulator_[AutoDiffXd](ad, context).AdvanceTo(0.5e-3)  # initialises at q0, one update
    q_d = [x.value() for x in ad.GetOutputPort("q_desired").Eval(context)]
    np.testing.assert_allclose(q_d, finals[1], rtol=1e-13, atol=1e-15)


@pytest.mark.parametrize(
    "call, kwargs, message",
    [
        ("set_gains", {"gain": 0.0}, "gain"),
        ("set_gains", {"damping": -1.0}, "damping"),
        ("set_gains", {"orientation_gain": 5.0}, "tool-axis task is off"),
        ("set_limits", {"q_lower": np.full(7, 1.0), "q_upper": np.full(7, 0.5)}, "below"),
        ("set_limits", {"v_max": np.zeros(7)}, "v_max"),
    ],
)
def test_bad_gains_and_limits_are_named(call, kwargs, message):
    _, clik, _ = make_clik()
    with pytest.raises(ValueError, match=message):
        getattr(clik, call)(clik.CreateDefaultContext(), **kwargs)
