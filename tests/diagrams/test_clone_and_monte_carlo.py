"""The demonstration diagram as Drake expects a diagram to behave: built once for every seed,
cloned into a second simulator with bit-identical logs, driven by MonteCarloSimulation."""

import numpy as np
import pytest
from pydrake.common import RandomGenerator
from pydrake.systems.analysis import MonteCarloSimulation, RandomSimulation, Simulator

from hemg_drake.diagrams.demonstration import (
    build_demonstration_diagram,
    initial_context,
    operator_plan,
    record_demonstration,
    run_demonstration,
)
from hemg_drake.scenario import load_scenario, shipped_scenario

DURATION = 0.6


@pytest.fixture(scope="module")
def pin():
    scenario = load_scenario(shipped_scenario("cotter_pin"), overrides=[f"duration={DURATION}"])
    return scenario, build_demonstration_diagram(scenario)


def _logs(built, diagram, seed):
    """Run ``diagram`` (``built.diagram`` or a clone of it) for ``seed``: both loggers' data."""
    context = initial_context(built, seed, diagram=diagram)
    simulator = Simulator(diagram, context)
    simulator.AdvanceTo(DURATION)
    logs = []
    for name in ("logger", "emg_logger"):
        logger = diagram.GetSubsystemByName(name)
        logs.append(logger.FindLog(context).data().copy())
    return logs


def test_demonstration_diagram_clones_with_bit_identical_logs(pin):
    scenario, built = pin
    clone = built.diagram.Clone()
    assert clone is not built.diagram
    for original, cloned in zip(_logs(built, built.diagram, 7), _logs(built, clone, 7)):
        assert original.shape == cloned.shape and original.size > 0
        assert original.tobytes() == cloned.tobytes()


def test_station_clones_and_converts_to_autodiff(pin):
    _, built = pin
    station = built.station.diagram
    assert station.Clone().num_input_ports() == station.num_input_ports()
    assert station.ToAutoDiffXd().num_output_ports() == station.num_output_ports()


def test_one_built_diagram_runs_every_seed_as_a_rebuilt_one_does(pin):
    scenario, built = pin
    first = run_demonstration(built, 3)
    second = run_demonstration(built, 4)
    rebuilt = record_demonstration(scenario, 4)
    assert second.p_WE.tobytes() == rebuilt.p_WE.tobytes()
    assert second.emg.tobytes() == rebuilt.emg.tobytes()
    assert not np.array_equal(first.p_MS, second.p_MS)  # the seed, not the diagram, varies
    again = run_demonstration(built, 3)
    assert again.gain.tobytes() == first.gain.tobytes()


def test_monte_carlo_simulation_draws_demonstrations_from_one_diagram(pin):
    _, built = pin
    diagram = built.diagram
    operator = diagram.GetSubsystemByName("operator")
    master = diagram.GetSubsystemByName("master")

    def make_simulator(generator):
        return Simulator(diagram)

    def stylus_travel(system, context):
        # How far the operator moved the stylus: it varies with the drawn plan.
        p_MS = master.GetOutputPort("p_MS").Eval(master.GetMyContextFromRoot(context))
        return float(np.linalg.norm(p_MS))

    results = MonteCarloSimulation(
        make_simulator=make_simulator, output=stylus_travel, final_time=DURATION,
        num_samples=3, generator=RandomGenerator(5),
    )  # fmt: skip
    outputs = [result.output for result in results]
    assert len(set(outputs)) == 3  # three different operators from one built diagram
    # Each sample is reproduced from its generator snapshot (same draws, same output).
    replay = RandomSimulation(
        make_simulator=make_simulator, output=stylus_travel, final_time=DURATION,
        generator=results[1].generator_snapshot,
    )  # fmt: skip
    assert replay == outputs[1]
    # The operator's draws came from the Context: its plan differs between samples.
    context = diagram.CreateDefaultContext()
    plans = []
    for seed in (1, 2):
        diagram.SetRandomContext(context, RandomGenerator(seed))
        simulator = Simulator(diagram, context)
        simulator.Initialize()
        plans.append(operator.plan(operator.GetMyContextFromRoot(simulator.get_context())))
    assert not np.array_equal(plans[0].times, plans[1].times)


def test_the_seed_gives_the_operator_the_plan_that_seed_perturbs(pin):
    # The draws put into the Context reproduce TaskPlan.perturbed(seed), numpy's draws, on
    # the diagram and on a clone (whose operator is a plain Diagram).
    scenario, built = pin
    for diagram in (built.diagram, built.diagram.Clone()):
        context = initial_context(built, 9, diagram=diagram)
        simulator = Simulator(diagram, context)
        simulator.Initialize()
        law = diagram.GetSubsystemByName("operator").GetSubsystemByName("law")
        plan = law.plan(law.GetMyContextFromRoot(context))
        expected = operator_plan(scenario, 9)
        np.testing.assert_array_equal(plan.times, expected.times)
        np.testing.assert_array_equal(plan.points, expected.points)
