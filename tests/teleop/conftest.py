"""Fixtures shared by the browser master's tests: the shipped cotter-pin scenario and a
loopback Meshcat."""

import pytest

from hemg_drake.diagrams.visualization import Visualization
from hemg_drake.scenario import load_scenario, shipped_scenario


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(shipped_scenario("cotter_pin"))


@pytest.fixture
def visualization():
    return Visualization(0)


@pytest.fixture
def meshcat(visualization):
    return visualization.meshcat
