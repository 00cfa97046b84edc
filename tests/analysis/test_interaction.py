"""Forces, energy, torque, tracking and the push's return, against hand values."""

import dataclasses as dc

import numpy as np
import pytest

from hemg_drake.analysis.interaction import (
    demonstrated_path,
    interaction_metrics,
    path_deviation,
    push_response,
)

T = np.linspace(0.0, 2.0, 201)  # 0.01 s


def test_forces_impulse_energy_torque_tracking_by_hand():
    # 0.5 s of a 4 N push back on a tool moving at 0.1 m/s into it, then free.
    touching = (T >= 0.5) & (T <= 1.0)
    f_WE = np.where(touching[:, None], [0.0, 0.0, -4.0], 0.0)
    v_WE = np.tile([0.0, 0.0, 0.1], (len(T), 1))
    p_WE = np.cumsum(v_WE, axis=0) * 0.01
    x_star = p_WE + [0.003, 0.0, 0.004]  # 5 mm behind throughout
    tau = np.zeros((len(T), 7))
    tau[50, 3] = -12.5
    f_block = np.zeros((len(T), 3))
    f_block[120] = [6.0, 8.0, 0.0]
    record = interaction_metrics(T, p_WE, v_WE, f_WE, x_star, tau=tau, f_block=f_block)
    assert record["contact_force_peak_n"] == 4.0
    assert record["contact_force_mean_n"] == 4.0
    # Trapezoid: 0.5 s at 4 N plus the two half-samples at the edges (0.01 s x 4 N).
    assert record["impulse_n_s"] == pytest.approx(2.0 + 0.04)
    assert record["energy_j"] == pytest.approx(0.4 * 0.51)  # 0.4 W for 0.51 s
    assert record["tracking_error_rms_m"] == pytest.approx(0.005)
    assert record["joint_torque_peak_nm"] == 12.5
    assert record["block_force_peak_n"] == 10.0
    assert record["block_impulse_n_s"] == pytest.approx(0.1)
    assert record["environment_force_peak_n"] == 10.0
    free = interaction_metrics(T, p_WE, v_WE, np.zeros_like(f_WE), p_WE)
    assert free["contact_force_mean_n"] == 0.0 and free["joint_torque_peak_nm"] is None


@dc.dataclass
class Demo:
    time: np.ndarray
    p_WE: np.ndarray


def test_push_returns_when_back_within_5_mm():
    # The path: a line along x at 0.05 m/s; the tool pushed 12 mm along y from 0.5 s to
    # 0.8 s, then back along y at 20 mm/s (within 5 mm 0.35 s after the release).
    path = np.column_stack([0.05 * T, np.zeros_like(T), np.zeros_like(T)])
    demos = [Demo(T, path), Demo(T * 1.1, path)]
    path_time, mean = demonstrated_path(demos, 2.0)
    np.testing.assert_allclose(mean, np.column_stack([0.05 * path_time, 0 * path_time,
                                                      0 * path_time]))  # fmt: skip
    y = np.clip(np.where(T < 0.8, (T - 0.5) * 0.04, 0.012 - (T - 0.8) * 0.02), 0.0, None)
    y[T < 0.5] = 0.0
    p_WE = path + np.column_stack([0 * T, y, 0 * T])
    # The path is points 5 ms apart (0.25 mm along x here): the nearest is within 0.13 mm.
    np.testing.assert_allclose(path_deviation(T, p_WE, path_time, mean), y, atol=1.3e-4)
    f_push = np.zeros((len(T), 3))
    f_push[(T >= 0.5 - 1e-9) & (T < 0.8 - 1e-9), 1] = 40.0
    response = push_response(T, p_WE, f_push, path_time, mean)
    assert response["release_s"] == pytest.approx(0.8)
    assert response["deviation_peak_m"] == pytest.approx(0.012, abs=1e-6)
    assert response["return_time_s"] == pytest.approx(0.35)  # first sample at 5.0 mm
    assert response["returned"]
    # Twice as slow back: 0.71 s, not returned; never back: None.
    slow = path + np.column_stack([0 * T, np.where(T < 0.8, y, 0.012 - (T - 0.8) * 0.01), 0 * T])
    assert push_response(T, slow, f_push, path_time, mean)["return_time_s"] == pytest.approx(0.71)
    stuck = path + np.column_stack([0 * T, np.where(T < 0.8, y, 0.012), 0 * T])
    never = push_response(T, stuck, f_push, path_time, mean)
    assert never["return_time_s"] is None and not never["returned"]
    assert push_response(T, p_WE, np.zeros_like(f_push), path_time, mean) is None
