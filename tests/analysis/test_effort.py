"""The shared-control study's measures (hemg_drake.analysis.effort) against hand values."""

import types

import numpy as np
import pytest

from hemg_drake.analysis.effort import (
    disagreement,
    hand_impulse,
    hand_work,
    interaction_metrics,
    phase_lags,
)
from hemg_drake.teleop.visual import STATE_SIZE

TIME = np.array([0.0, 1.0, 2.0])
# |F| = 5, 0, 10 N; F . v = 3, 0, -6 W.
FORCE = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0], [6.0, 8.0, 0.0]])
VELOCITY = np.array([[1.0, 0.0, 0.0], [1.0, 1.0, 1.0], [-1.0, 0.0, 0.0]])


def test_hand_impulse_is_the_trapezoid_of_the_force_norm():
    assert hand_impulse(TIME, FORCE) == pytest.approx(0.5 * (5 + 0) + 0.5 * (0 + 10))


def test_hand_work_counts_only_the_power_the_hand_puts_in():
    # max(F . v, 0) = 3, 0, 0: the trapezoid 1.5 J (the -6 W the device gives back: none).
    assert hand_work(TIME, FORCE, VELOCITY) == pytest.approx(1.5)


def test_disagreement_is_the_mean_distance():
    command = np.zeros((2, 3))
    policy = np.array([[0.0, 0.03, 0.04], [0.0, 0.0, 0.01]])
    assert disagreement(command, policy) == pytest.approx(0.5 * (0.05 + 0.01))


def test_phase_lags_early_late_and_missed():
    time = np.arange(6.0)
    offline = np.array([0, 0, 1, 1, 2, 2])
    # The online phase is 1 one sample before the model's change at t = 2 (lag -1 s) and 2
    # one sample after its change at t = 4 (+1 s).
    np.testing.assert_allclose(phase_lags(time, [0, 1, 1, 1, 1, 2], offline), [-1.0, 1.0])
    # Never 2 before the end: NaN.
    lags = phase_lags(time, [0, 1, 1, 1, 1, 1], offline)
    assert lags[0] == -1.0 and np.isnan(lags[1])


def test_interaction_metrics_of_a_log():
    visual = np.zeros((3, STATE_SIZE))
    visual[-1, 0] = 1.25  # the plan clock at 1.25 s when the run ends at 2 s
    visual[-1, 6] = 1.0  # given up
    signals = {
        "time": TIME[:, None], "hand_force": FORCE, "v_MS": VELOCITY,
        "passivity_energy": np.array([[0.0], [-2e-3], [1e-3]]), "visual_state": visual,
        "assist.x_policy": np.array([[0.0, 0.0, 0.02]] * 3),
    }  # fmt: skip
    demo = types.SimpleNamespace(time=TIME, p_WE_desired=np.zeros((3, 3)))
    result = interaction_metrics(signals, demo)
    assert result == pytest.approx({
        "hand_impulse_n_s": 7.5, "hand_work_j": 1.5, "passivity_energy_min_j": -2e-3,
        "gave_up": 1.0, "held_s": 0.75, "disagreement_m": 0.02,
    })  # fmt: skip


def test_viterbi_free_durations_against_brute_force():
    # Every path of 3 states over 5 steps scored by hand: start + emissions + the moves
    # between different states (a stay costs nothing).
    import itertools

    from hemg_drake.analysis.effort import viterbi_free_durations

    rng = np.random.default_rng(4)
    log_emission = rng.normal(size=(5, 3))
    log_start = np.log([0.6, 0.3, 0.1])
    # Self-transitions unlikely in the matrix: only a free stay keeps a state.
    log_a = np.log([[0.01, 0.9, 0.09], [0.05, 0.01, 0.94], [0.5, 0.49, 0.01]])

    def score(path):
        total = log_start[path[0]] + log_emission[0, path[0]]
        for t in range(1, 5):
            move = 0.0 if path[t] == path[t - 1] else log_a[path[t - 1], path[t]]
            total += move + log_emission[t, path[t]]
        return total

    best = max(itertools.product(range(3), repeat=5), key=score)
    assert any(a == b for a, b in zip(best, best[1:]))  # a stay: the free durations matter
    np.testing.assert_array_equal(viterbi_free_durations(log_emission, log_start, log_a), best)
