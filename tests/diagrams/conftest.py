"""Fixtures shared by the diagram tests: the shipped cotter-pin scenario."""

import pytest

from hemg_drake.scenario import load_scenario, shipped_scenario


@pytest.fixture(scope="module")
def pin_scenario():
    return load_scenario(shipped_scenario("cotter_pin"))
