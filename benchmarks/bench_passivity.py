"""Delayed force feedback with and without the time-domain passivity controller.

The loop of ``hemg_drake.teleop.delay_loop`` (its physics checked in
``tests/teleop/test_feedback.py``): the Touch X stylus held by a hand (300 N/m, 5 N s/m, the
simulated operator's impedance), the slave following it through a ``WorkspaceMap`` delay of
n samples into a stiff environment (a 500 N/m spring in W), the spring's force fed back
(``ForceFeedback``, mode "force", gain 1) through another n samples. The stylus starts 5 mm
off the spring's rest. Prints, per one-way delay, the largest stylus excursion over the last
second of 3 s, plain and with ``passivity="tdpa"``, and with ``--figure PATH`` plots it
(docs/img/study_delay_loop.png).
"""

import argparse

import numpy as np

from hemg_drake.teleop.delay_loop import simulate_delayed_spring_loop

DELAYS_MS = (0, 2, 5, 10, 20, 50, 100, 200)
DURATION = 3.0


def excursion(delay_steps, passivity, k_env=500.0):
    """Largest |x| of the stylus (m) over the last second, and the observer's least E (J)."""
    x, energy = simulate_delayed_spring_loop(
        delay_steps, passivity, duration=DURATION, environment_stiffness=k_env
    )
    return max(x[-100:]), float(energy.min()) if energy.size else 0.0


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figure", help="write the plot here (PNG)")
    args = parser.parse_args()
    rows = {}
    for delay in DELAYS_MS:
        plain, _ = excursion(delay, "none")
        passive, least = excursion(delay, "tdpa")
        rows[delay] = (plain, passive)
        print(
            f"delay {delay:3d} ms each way: last-second excursion plain {1e3 * plain:7.3f} "
            f"mm, passive {1e3 * passive:7.3f} mm (observer's least energy {least:.1e} J)"
        )
    if args.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from hemg_drake.viz.figures import save_figure

        figure, ax = plt.subplots(figsize=(5.5, 3.2))
        delays = np.array(DELAYS_MS, dtype=float)
        floor = 1e-6  # mm, so that a settled loop shows on the log axis
        for index, label in ((0, "force feedback"), (1, "with the passivity controller")):
            values = np.maximum([1e3 * rows[d][index] for d in DELAYS_MS], floor)
            ax.semilogy(delays, values, "o-", label=label)
        ax.set_xlabel("one-way delay (ms), both directions")
        ax.set_ylabel("stylus excursion, last 1 s (mm)")
        ax.set_title("stylus on a 500 N/m delayed spring, hand 300 N/m", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        figure.tight_layout()
        save_figure(figure, args.figure)
        print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
