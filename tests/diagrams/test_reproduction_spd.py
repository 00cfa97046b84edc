"""The reproduction diagram with ``reproduction.stiffness: spd``: the shape reaches the station,
every logged shape is SPD and bounded, the lift is the soft direction, and it clones."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from hemg_drake.control.impedance import CartesianImpedancePd
from hemg_drake.control.pd import VariableGainPd
from hemg_drake.diagrams.reproduction import build_reproduction_diagram, run_reproduction
from hemg_drake.scenario import Scenario
from hemg_drake.tasks.cotter_pin import DEFAULT_POSITION

START = np.array(DEFAULT_POSITION)


def scenario(*changes):
    return Scenario().replaced(
        ["task=cotter_pin", "duration=1.0", "reproduction.weighting=temporal", *changes]
    )


@pytest.mark.parametrize("normalisation", ["determinant", "softest"])
def test_spd_reproduction_applies_a_bounded_spd_shape_soft_along_the_lift(model, normalisation):
    spd = scenario("reproduction.stiffness=spd",
                   f"reproduction.stiffness_normalisation={normalisation}")  # fmt: skip
    built = build_reproduction_diagram(spd, model, scene=False)
    assert isinstance(built.station.diagram.GetSubsystemByName("pd"), CartesianImpedancePd)
    log = run_reproduction(built).log
    shapes = log.stiffness_shape.reshape(-1, 3, 3)
    np.testing.assert_array_equal(shapes, np.swapaxes(shapes, 1, 2))
    values, vectors = np.linalg.eigh(shapes)
    assert values.min() > 0
    assert (values[:, -1] / values[:, 0]).max() <= 10.0 * (1 + 1e-9)
    if normalisation == "determinant":
        np.testing.assert_allclose(values.prod(axis=1), 1.0, rtol=1e-9)
    else:
        np.testing.assert_allclose(values[:, 0], 1.0, rtol=1e-9)
    # The demonstrations vary along the lift (z) only: z is the softest direction.
    assert np.abs(vectors[:, 2, 0]).min() > 0.95
    # The reference is the scalar run's (the shape changes the station, not the policy),
    # and the arm follows it.
    scalar = run_reproduction(build_reproduction_diagram(scenario(), model, scene=False)).log
    np.testing.assert_array_equal(log.x_star, scalar.x_star)
    assert np.max(np.linalg.norm(log.p_WE - log.x_star, axis=1)) < 0.01


def test_scalar_mode_keeps_eq_20s_pd_and_log(model):
    built = build_reproduction_diagram(scenario(), model, scene=False)
    assert type(built.station.diagram.GetSubsystemByName("pd")) is VariableGainPd
    assert not built.station.diagram.HasInputPort("stiffness_shape")
    assert "stiffness_shape" not in run_reproduction(built, duration=0.05).log.arrays()


def test_the_spd_diagram_clones_and_runs_bit_identical(model):
    built = build_reproduction_diagram(scenario("reproduction.stiffness=spd"), model, scene=False)
    states = []
    for diagram in (built.diagram, built.diagram.Clone()):
        simulator = Simulator(diagram)
        # A converted plant drops its default positions (SlaveStation.set_start).
        built.station.set_start(simulator.get_mutable_context(), diagram.GetSubsystemByName(
            built.station.diagram.get_name()))  # fmt: skip
        simulator.AdvanceTo(0.05)
        groups = simulator.get_context().get_discrete_state()
        states.append(np.concatenate(
            [groups.get_vector(i).CopyToVector() for i in range(groups.num_groups())]
        ))  # fmt: skip
    np.testing.assert_array_equal(states[0], states[1])
