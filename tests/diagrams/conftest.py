"""Fixtures shared by the diagram tests: the shipped cotter-pin scenario, and an HSMM of
three noisy lifts from the pin's ring."""

import numpy as np
import pytest

from hemg_drake.learning.hsmm import HSMM
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.tasks.cotter_pin import DEFAULT_POSITION


@pytest.fixture(scope="module")
def pin_scenario():
    return load_scenario(shipped_scenario("cotter_pin"))


@pytest.fixture(scope="module")
def model():
    """An HSMM over [x, xdot, k] of three noisy 5 cm lifts along z from the pin's ring (where
    the default cotter-pin plan starts), with a stiffness that rises."""
    rng = np.random.default_rng(0)
    demos = []
    for _ in range(3):
        t = np.linspace(0.0, 1.0, 101)
        s = t**3 * (10 - 15 * t + 6 * t**2)
        lift = np.outer(0.05 * s, [0.0, 0.0, 1.0])
        x = np.array(DEFAULT_POSITION) + lift + rng.normal(0, 5e-4, (101, 3))
        k = 20.0 + 130.0 * s + rng.normal(0, 2.0, 101)
        demos.append(np.column_stack([x, np.gradient(x, 0.01, axis=0), k]))
    return HSMM(3, init="time", reg_covar=0.1, n_iter=10, random_state=0).fit(demos)
