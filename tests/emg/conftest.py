"""Helpers for the EMG tests: run a small diagram and read its ports per 200 Hz sample."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from hemg_drake.emg.sources import MYO_PERIOD


def _simulate(builder, ports, n_samples):
    """Build, run n_samples MYO periods, return {name: array (n_samples, size)}.

    A logger publishing at t_k sees the value before the update at t_k, so
    row k of the returned array is what the port held after update k.
    """
    loggers = {
        name: LogVectorOutput(port, builder, publish_period=MYO_PERIOD)
        for name, port in ports.items()
    }
    diagram = builder.Build()
    simulator = Simulator(diagram)
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


def _held_signal(values):
    """A TrajectorySource holding values[k] around t_k = k / 200 s.

    Breaks sit a quarter period before each sample instant, away from both the
    sources' updates (t_k) and the envelope's (t_k + period / 2), so every
    system reads values[k] for sample k whatever the rounding of k * period.
    """
    values = np.asarray(values, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    breaks = np.concatenate([[0.0], (np.arange(1, len(values) + 1) - 0.25) * MYO_PERIOD])
    knots = np.vstack([values, values[-1:]]).T
    return TrajectorySource(PiecewisePolynomial.ZeroOrderHold(breaks, knots))


@pytest.fixture
def held_signal():
    return _held_signal


@pytest.fixture
def builder():
    return DiagramBuilder()
