"""The reproduction's record: Table II measured three ways, and success checked on the physics."""

import numpy as np
import pytest

from hemg_drake import evaluation
from hemg_drake.diagrams.reproduction import ReproductionLog, ReproductionResult
from hemg_drake.learning.demos import Demonstration


def _pull(t, rise, z0=0.12, end_time=3.0):
    """A tool point rising by ``rise`` over ``end_time`` s (minimum-jerk), at rest after."""
    tau = np.clip(t / end_time, 0.0, 1.0)
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    p = np.column_stack([np.full_like(t, 0.64), np.full_like(t, -0.84), z0 + rise * s])
    return p, np.gradient(p, t, axis=0)


def _demo(seed, rise):
    t = np.arange(0, 4.0, 0.01)
    p, v = _pull(t, rise)
    n, zeros = len(t), np.zeros((len(t), 3))
    force = zeros.copy()
    force[:, 2] = -20.0 * np.exp(-((t - 1.0) ** 2) / 0.05)  # a 20 N pull at t = 1 s
    return Demonstration(
        seed=seed, time=t, p_WE=p, v_WE=v, p_MS=zeros, p_WE_desired=p, envelope=np.zeros(n),
        activation=np.zeros(n), gain=np.full(n, 100.0), f_WE=force,
        emg_time=np.arange(2 * n) * 0.005, emg=np.zeros((2 * n, 8)),
        muscle_activation=np.zeros(2 * n),
    )  # fmt: skip


def _result(rise, *, force=20.0, pin_out=True, dip=0.0):
    t = np.arange(0, 4.0, 0.01)
    p, v = _pull(t, rise)
    p[50:60, 2] -= dip
    n = len(t)
    f_WE = np.zeros((n, 3))
    f_WE[100, 2] = -force
    log = ReproductionLog(
        time=t, x_star=p, xdot_star=v, k_star=np.full(n, 100.0), h=np.ones((n, 1)),
        p_WE=p, v_WE=v, f_WE=f_WE, F_tr=np.zeros((n, 3)),
    )  # fmt: skip
    return ReproductionResult(log=log, q0=np.zeros(7), pin_displacement=0.06, pin_out=pin_out)


@pytest.fixture
def demos():
    return [_demo(c, rise) for c, rise in enumerate((0.095, 0.10, 0.105))]


def test_a_reproduction_like_the_demonstrations_succeeds_and_its_floor_is_reported(demos):
    record = evaluation.task_metrics("cotter_pin", demos, _result(0.10))
    assert record["success"] and all(record["success_checks"].values())
    # The reproduction is the middle demonstration itself: the lead figure is its offset
    # from the mean of all three (zero), each demonstration's own against the others' mean.
    assert record["position_rmse_m"] == pytest.approx(0.0, abs=1e-9)
    floor = record["table_ii"]["demonstrations_leave_one_out"]["position_rmse_m"]
    assert len(floor) == 3 and max(floor) > 0.004
    assert record["success_limits"]["peak_force_n"] == pytest.approx(1.5 * 20.0, rel=1e-3)
    assert record["table_ii"]["paper"]["position_rmse_m"] == 0.0022


@pytest.mark.parametrize(
    "result, failed",
    [
        (dict(rise=0.13), "no overshoot"),  # ends 2.5 cm above the highest demonstration
        (dict(rise=0.10, force=206.0), "force within limit"),
        (dict(rise=0.10, dip=0.04), "not pushed into the fixture"),
        (dict(rise=0.10, pin_out=False), "pin out"),
    ],
)
def test_success_checks_the_physics(demos, result, failed):
    record = evaluation.task_metrics("cotter_pin", demos, _result(**result))
    assert record["success"] is False
    assert record["success_checks"][failed] is False
    assert sum(not ok for ok in record["success_checks"].values()) == 1
