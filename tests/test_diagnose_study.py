"""benchmarks/diagnose_assist_study.py on hand-made trial folders: every column against
values worked out by hand from the logs written here (not by the code under test)."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from hemg_drake.fileio import save_npz_atomic
from hemg_drake.learning.demos import Demonstration, save_dataset
from hemg_drake.teleop.visual import C, GAVE_UP, S, STATE_SIZE

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
T = np.arange(400) * 0.01  # 4 s of 10 ms log samples


@pytest.fixture(scope="module")
def diagnose():
    spec = importlib.util.spec_from_file_location("diagnose", BENCHMARKS / "diagnose_assist_study.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _trial(folder, name, labels, metrics, *, rise, f_WE, activation, weight=None):
    """One finished trial: trial.json, run/dataset.npz and run/interaction.npz."""
    n = len(T)
    p_WE = np.column_stack([np.full(n, 0.6), np.full(n, -0.8), 0.12 + rise])
    demo = Demonstration(
        seed=1, time=T, p_WE=p_WE, v_WE=np.gradient(p_WE, T, axis=0), p_MS=np.zeros((n, 3)),
        p_WE_desired=p_WE, envelope=np.zeros(n), activation=activation, gain=np.full(n, 300.0),
        f_WE=f_WE, emg_time=np.arange(2 * n) * 0.005, emg=np.zeros((2 * n, 8)),
        muscle_activation=np.zeros(2 * n),
    )  # fmt: skip
    visual = np.zeros((n, STATE_SIZE))
    visual[:, S] = 0.5 * T  # the plan clock runs at half speed
    visual[150, C] = [0.003, -0.004, 0.0]  # the largest correction: 5 mm
    visual[300:, GAVE_UP] = 1.0  # gives up at sample 300: plan clock 1.5 s
    logs = {"demo0.time": T[:, None], "demo0.visual_state": visual}
    if weight is not None:
        logs["demo0.assist.weight"] = weight[:, None]
    run = folder / "trials" / name / "run"
    run.mkdir(parents=True)
    save_dataset(run / "dataset.npz", [demo])
    save_npz_atomic(run / "interaction.npz", **logs)
    record = {"status": "done", "labels": labels, "metrics": metrics}
    (run.parent / "trial.json").write_text(json.dumps(record), encoding="utf-8")


def test_pin_swings_correction_and_weight(diagnose, tmp_path):
    # The tool rises 9 cm, falls to 1 cm (a swing), rises to 8.5, falls to 1.5 (a second),
    # then to 5 cm: two swings. Working (activation > 0.5) for samples 100-199.
    rise = np.interp(T, [0, 1, 2, 2.5, 3, 3.99], [0, 0.09, 0.01, 0.085, 0.015, 0.05])
    activation = np.where((T >= 1.0) & (T < 2.0), 0.7, 0.1)
    weight = np.where(activation > 0.5, 0.02, 0.2)
    labels = {"operator": "nominal", "delay_ms": "250", "mode": "emg"}
    _trial(tmp_path, "a", labels, {"demonstration.pin_out": 1.0}, rise=rise,
           f_WE=np.zeros((len(T), 3)), activation=activation, weight=weight)  # fmt: skip
    # A failed trial is not read, though its logs are there.
    other = {"operator": "nominal", "delay_ms": "0", "mode": "none"}
    _trial(tmp_path, "b", other, {"demonstration.pin_out": 1.0}, rise=rise,
           f_WE=np.zeros((len(T), 3)), activation=activation, weight=weight)  # fmt: skip
    (tmp_path / "trials" / "b" / "trial.json").write_text(
        json.dumps({"status": "failed", "labels": other, "metrics": {}}), encoding="utf-8")
    cells = diagnose.diagnose(tmp_path)
    assert list(cells) == [("nominal", 250, "emg")]
    (row,) = cells[("nominal", 250, "emg")]
    assert row["swings"] == 2
    assert row["correction_mm"] == pytest.approx(5.0)
    assert row["held_at_s"] == pytest.approx(1.5)
    assert row["w_mean"] == pytest.approx((300 * 0.2 + 100 * 0.02) / 400)
    assert row["w_working"] == pytest.approx(0.02)


def test_swings_need_a_rise_first(diagnose):
    assert diagnose.swings(np.array([0.0, 0.01, 0.0, 0.079, 0.01])) == 0  # never at 8 cm
    assert diagnose.swings(np.array([0.0, 0.08, 0.05, 0.08, 0.019, 0.019, 0.09])) == 1
    assert diagnose.swings(np.array([0.09, 0.02, 0.09])) == 0  # 2 cm is not below 2 cm


def test_drawing_touches_and_ink_pieces(diagnose, tmp_path):
    # Pen contacts (samples): 50-80, a 3-sample touch at 100-103, 150-180 and 183-200 (a
    # 30 ms lift: one stroke with a break), 250-290. Five touches, three ink pieces (the
    # short touch is too short for ink; the lift too short to end a stroke).
    f_WE = np.zeros((len(T), 3))
    for a, b in [(50, 80), (100, 103), (150, 180), (183, 200), (250, 290)]:
        f_WE[a:b, 2] = 4.0
    labels = {"operator": "slow", "delay_ms": "0", "mode": "none"}
    _trial(tmp_path, "d", labels, {"demonstration.strokes": 3.0}, rise=np.zeros(len(T)),
           f_WE=f_WE, activation=np.full(len(T), 0.6))  # fmt: skip
    (row,) = diagnose.diagnose(tmp_path)[("slow", 0, "none")]
    assert (row["touches"], row["pieces"]) == (5, 3)
    assert "swings" not in row and "w_mean" not in row  # mode none logs no weight
