"""Helpers for the EMG tests: run a small diagram and read its ports per 200 Hz sample."""

import pytest
from pydrake.common import RandomGenerator
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from hemg_drake.emg.config import MYO_PERIOD
from hemg_drake.emg.synthetic import held_samples


def _simulate(builder, ports, n_samples, seed=0):
    """Build, seed the Context, run n_samples MYO periods, return {name: (n_samples, size)}.

    A logger publishing at t_k sees the value before the update at t_k, so
    row k of the returned array is what the port held after update k.
    """
    loggers = {
        name: LogVectorOutput(port, builder, publish_period=MYO_PERIOD)
        for name, port in ports.items()
    }
    diagram = builder.Build()
    simulator = Simulator(diagram)
    diagram.SetRandomContext(simulator.get_mutable_context(), RandomGenerator(seed))
    simulator.AdvanceTo(n_samples * MYO_PERIOD)
    context = simulator.get_context()
    result = {}
    for name, logger in loggers.items():
        data = logger.FindLog(context).data().T
        assert len(data) == n_samples + 1, "logger missed a sample"
        result[name] = data[1:]
    return result


@pytest.fixture
def simulate():
    return _simulate


@pytest.fixture
def held_signal():
    return held_samples


@pytest.fixture
def builder():
    return DiagramBuilder()
