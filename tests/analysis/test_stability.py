"""The loop's stability by linearisation, against closed forms, finite differences and the
delay study's simulated onset."""

import numpy as np
import pytest
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import DiscreteTimeDelay, Gain

from hemg_drake.analysis.stability import (
    build_hold_loop,
    carry_hold,
    discrete_state,
    discrete_update,
    discrete_update_jacobian,
    hold,
    loop_stability,
    onset_delay,
    set_discrete_state,
    spectrum,
)
from hemg_drake.scenario import load_scenario, shipped_scenario


@pytest.fixture(scope="module")
def pin():
    return load_scenario(shipped_scenario("cotter_pin"))


@pytest.mark.parametrize("a, d", [(0.5, 1), (0.9, 3), (1.2, 4), (-0.7, 5)])
def test_spectrum_of_a_delayed_gain_loop_is_the_root_of_its_characteristic_polynomial(a, d):
    # u = a y through Drake's delay of d samples, whose output is itself a latched sample
    # (d + 1 states): the loop's characteristic polynomial is z^(d + 1) = a, so every
    # eigenvalue has modulus |a|^(1/(d + 1)).
    builder = DiagramBuilder()
    delay = builder.AddSystem(DiscreteTimeDelay(1e-3, d, 1))
    gain = builder.AddSystem(Gain(a, 1))
    builder.Connect(delay.get_output_port(), gain.get_input_port())
    builder.Connect(gain.get_output_port(), delay.get_input_port())
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    result = spectrum(diagram, context, delay_ms=d, period=1e-3)
    assert result.spectral_radius == pytest.approx(abs(a) ** (1.0 / (d + 1)), rel=1e-12)
    assert result.stable == (abs(a) < 1.0)
    assert result.num_states == d + 1


def test_hold_loop_jacobian_is_the_finite_difference_of_its_update(pin):
    # The AutoDiffXd conversion of master, map, station (pin scene) and feedback, against
    # central differences of the double loop's update at the carried hold.
    source = hold(pin, gain=50.0, settle_time=0.2)
    delayed = pin.replaced(["mapping.delay_steps=2", "feedback.delay_steps=2"])
    diagram = build_hold_loop(delayed, gain=50.0)
    context = diagram.CreateDefaultContext()
    carry_hold(*source, diagram, context)
    x0 = discrete_state(context)
    jacobian = discrete_update_jacobian(diagram, context)

    def update(x):
        set_discrete_state(context, x)
        return discrete_update(diagram, context)

    h = 1e-7
    numeric = np.column_stack(
        [(update(x0 + h * e) - update(x0 - h * e)) / (2 * h) for e in np.eye(len(x0))]
    )
    np.testing.assert_allclose(jacobian, numeric, rtol=1e-4, atol=2e-4)


def test_carried_hold_is_an_equilibrium_of_the_delayed_loop(pin):
    results = loop_stability(pin, [0, 10], gain=10.0, settle_time=1.0)
    for result in results:
        assert result.equilibrium_residual < 1e-8
    assert results[1].num_states > results[0].num_states + 2 * 10 * 3  # two delay lines


def test_force_loop_onset_matches_the_delay_studys_simulation(pin):
    # docs/studies.md: simulated, the force loop oscillates at 25 ms, not at 0; the
    # position-error PD and the loop without feedback stay stable at every delay.
    grid = [0, 25, 50, 100]
    force = loop_stability(pin, grid, gain=10.0, settle_time=1.0)
    assert onset_delay(force) == 25
    assert 3.0 < force[1].frequency_hz < 10.0  # a few hertz, as the stylus oscillated
    for changes in (["feedback.gain=0"], ["feedback.mode=position_error"]):
        results = loop_stability(pin.replaced(changes), grid[:3], gain=10.0, settle_time=1.0)
        assert onset_delay(results) is None, changes
    # The passivity controller is inactive about a hold: the same linearised loop.
    passive = loop_stability(pin.replaced(["feedback.passivity=tdpa"]), grid[:2], gain=10.0,
                             settle_time=1.0)  # fmt: skip
    for plain, with_tdpa in zip(force, passive):
        assert with_tdpa.spectral_radius == pytest.approx(plain.spectral_radius, rel=1e-9)


def test_delays_must_be_whole_samples(pin):
    with pytest.raises(ValueError, match="not a whole number"):
        loop_stability(pin, [2.5], gain=10.0)


def test_cli_prints_the_onset_and_refuses_a_partial_sample(run_cli, tmp_path):
    figure = tmp_path / "stability.png"
    code, out, err = run_cli(
        ["stability", "cotter_pin", "--delays", "0", "25", "--gains", "10", "-o", str(figure)]
    )
    assert code == 0, err
    assert "force, K = 10: unstable from 25 ms" in out
    assert figure.stat().st_size > 0
    code, out, err = run_cli(["stability", "cotter_pin", "--delays", "2.5"])
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [
        "hemg-drake stability: error: --delays 2.5: a delay must be a whole number of the "
        "master's 1 ms samples, >= 0"
    ]
