"""Time the tracking reproduction's re-plan: one 10 ms step of the LQR tracker (issue 15 s1).

An HSMM of N = 18 states over D = 7 ([x, xdot, k]) fitted to three drawing-sized
demonstrations (T = 1,000 steps), and one of N = 4 states (the cotter pin's size). For each
weighting and horizon H: the one-off table of gains (``"temporal"``), the median and 95th
percentile of one re-plan (:class:`HsmmLqrPolicy.step`), and one period of
``HsmmLqrReproducer`` in a Drake Simulator (its output fed back as p_WE), beside
``HsmmGmrReproducer`` (eqs. 15-18). Run: ``.venv/bin/python benchmarks/bench_tracker.py``.
"""

import argparse
import time

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from hemg_drake.learning.hsmm import HSMM
from hemg_drake.learning.reproduce import HsmmLqrPolicy
from hemg_drake.learning.systems import HsmmGmrReproducer, HsmmLqrReproducer

DT = 0.01


def demos(n_steps, seed=0):
    """Three noisy demonstrations of a 3-D drawing-like path with a stiffness channel."""
    rng = np.random.default_rng(seed)
    out = []
    for c in range(3):
        s = np.linspace(0.0, 1.0, n_steps) ** (1.0 + 0.05 * c)
        x = np.stack([0.2 * s, 0.05 * np.sin(6 * np.pi * s), 0.01 * np.cos(3 * np.pi * s)], 1)
        x += 2e-4 * rng.standard_normal(x.shape)
        k = 200.0 + 100.0 * np.sin(np.pi * s)[:, None]
        out.append(np.hstack([x, np.gradient(x, DT, axis=0), k]))
    return out


def time_policy(model, start, weighting, horizon, n_steps):
    begin = time.perf_counter()
    policy = HsmmLqrPolicy(model, weighting=weighting, dt=DT, horizon=horizon)
    build = time.perf_counter() - begin
    x, xdot, predicted = start, np.zeros(3), policy.forward.initial()
    times = []
    for t in range(n_steps):
        begin = time.perf_counter()
        _, _, x, xdot, predicted = policy.step(t, x, xdot, predicted)
        times.append(time.perf_counter() - begin)
    return build, np.median(times), np.percentile(times, 95)


def time_system(system, n_steps):
    builder = DiagramBuilder()
    builder.AddSystem(system)
    builder.Connect(system.GetOutputPort("x_star"), system.GetInputPort("p_WE"))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.5 * DT)  # first update outside the timing
    begin = time.perf_counter()
    simulator.AdvanceTo((n_steps + 0.5) * DT)
    return (time.perf_counter() - begin) / n_steps


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300, help="steps timed per case")
    args = parser.parse_args()
    data = demos(1000)
    start = data[0][0, :3]
    models = {
        n: HSMM(n, init="time", reg_covar=0.1, n_iter=10, random_state=0).fit(data) for n in (18, 4)
    }
    print("re-plan of the LQR tracker, one 10 ms step (2 shared cores; us = microseconds)")
    print(f"{'N':>3} {'weighting':>9} {'H':>4} {'table (s)':>10} {'step median':>12} "
          f"{'step p95':>10} {'in Drake':>10}")  # fmt: skip
    for n, model in models.items():
        for weighting in ("temporal", "forward"):
            for horizon in (50, 100):
                build, median, p95 = time_policy(model, start, weighting, horizon, args.steps)
                system = HsmmLqrReproducer(
                    model=model, start=start, dt=DT, weighting=weighting, horizon=horizon
                )
                drake = time_system(system, args.steps)
                table = f"{build:.3f}" if weighting == "temporal" else "-"
                times = f"{median * 1e6:>9.0f} us {p95 * 1e6:>7.0f} us {drake * 1e6:>7.0f} us"
                print(f"{n:>3} {weighting:>9} {horizon:>4} {table:>10} {times}")
        for weighting in ("temporal", "forward"):
            drake = time_system(
                HsmmGmrReproducer(model=model, start=start, dt=DT, weighting=weighting),
                args.steps,
            )
            print(f"{n:>3} {weighting:>9}  eqs. 15-18 (HsmmGmrReproducer) in Drake: "
                  f"{drake * 1e6:.0f} us")  # fmt: skip


if __name__ == "__main__":
    main()
