"""Time the learning core: HSMM fit, numba compile, reproduction step, hmmlearn yardstick.

Fit: N = 18 states, C = 3 demonstrations of T = 1,000 steps, D = 7 ([x, xdot, k]),
max_duration 150, 20 EM iterations (tol = 0, so all 20 run). Reproduction: one
step of each weighting, N = 18, D = 7. Run: ``.venv/bin/python benchmarks/bench_learning.py``.
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from hemg_drake.learning import _kernels
from hemg_drake.learning.gmr import gaussian_log_pdf
from hemg_drake.learning.hsmm import HSMM
from hemg_drake.learning.reproduce import WEIGHTINGS, reproduce

NOISE = 2e-4
N_STATES, N_DEMOS, N_STEPS, MAX_DURATION, N_ITER, DT = 18, 3, 1000, 150, 20, 0.01


def drawing_demos(seed=0):
    """Three noisy demonstrations of a 3-D drawing-like path with a stiffness channel."""
    rng = np.random.default_rng(seed)
    demos = []
    for c in range(N_DEMOS):
        s = np.linspace(0.0, 1.0, N_STEPS) ** (1.0 + 0.05 * c)
        lift = np.maximum(0.0, np.sin(6 * np.pi * s + 1.0))  # three strokes, pen lifts between
        x = np.stack([0.2 * s, 0.05 * np.sin(6 * np.pi * s), 0.01 * lift], axis=1)
        x += NOISE * rng.standard_normal(x.shape)
        xdot = np.gradient(x, DT, axis=0)
        k = 350.0 - 150.0 * lift[:, None]  # stiff while the pen is down
        demos.append(np.hstack([x, xdot, k]))
    return demos


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
        "k.backward(e, la, ld, a, ai, np.logaddexp.reduce(a[-1])); print(time.perf_counter() - t)"
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
    parser.parse_args()
    demos = drawing_demos()

    cold, cached = compile_times()
    print(f"numba kernels, first call: {cold:.2f} s with an empty cache (compile), "
          f"{cached:.2f} s from the cache (cache=True)")

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

    log_parameters = model._log_parameters()
    log_emission = gaussian_log_pdf(demos[0], model.means_, model.covariances_)
    numba_s, fast = timed(lambda: _kernels.forward(log_emission, *log_parameters)[0], repeat=3)
    numpy_s, slow = timed(lambda: numpy_forward(log_emission, *log_parameters), repeat=1)
    assert np.allclose(fast, slow, rtol=1e-9, atol=1e-6)  # same recursion, log-space round-off
    print(f"forward recursion of one demo (T={N_STEPS}): numba {1e3 * numba_s:.1f} ms, "
          f"numpy per time step {1e3 * numpy_s:.1f} ms ({numpy_s / numba_s:.0f}x)")

    try:
        from hmmlearn.hmm import GaussianHMM
    except ImportError:
        print("hmmlearn not installed: no yardstick")
        return
    samples = np.concatenate(demos)
    # hmmlearn's min_covar is absolute: standardise so that it fits every column.
    samples = (samples - samples.mean(axis=0)) / samples.std(axis=0)
    lengths = [len(d) for d in demos]
    hmm = GaussianHMM(N_STATES, covariance_type="full", n_iter=N_ITER, tol=0.0, random_state=0)
    seconds, _ = timed(lambda: hmm.fit(samples, lengths), repeat=1)
    print(f"hmmlearn GaussianHMM fit, same data, {N_ITER} iterations: {seconds:.2f} s "
          f"(an ordinary HMM, no durations)")


if __name__ == "__main__":
    main()
