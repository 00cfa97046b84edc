"""The teleoperation loop's stability against delay by linearisation, beside the delay
study's simulation (docs/studies.md: the force loop oscillates from 25 ms, the position-error
PD and the loop without feedback never).

    python benchmarks/bench_stability.py [--figure docs/img/stability.png]

Prints the spectral radius per delay for the pin's force loop at K = k_min and k_max, the
position-error PD and no feedback, the first unstable delay of each, and the time it took.
"""

import argparse
import time

from hemg_drake.analysis.stability import loop_stability, onset_delay
from hemg_drake.scenario import load_scenario, shipped_scenario

DELAYS_MS = [0, 5, 10, 15, 20, 25, 30, 40, 50, 75, 100, 125, 150, 175, 200]
# The delay study's grid and where its simulation saw the force loop oscillate.
STUDY_GRID_MS = [0, 25, 50, 100, 150, 200]
SIMULATED_ONSET_MS = 25


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figure", help="write the figure here")
    args = parser.parse_args()
    pin = load_scenario(shipped_scenario("cotter_pin"))
    cases = {
        f"force, K = {pin.emg.k_min:g}": (pin, pin.emg.k_min),
        f"force, K = {pin.emg.k_max:g}": (pin, pin.emg.k_max),
        f"position-error PD, K = {pin.emg.k_min:g}": (
            pin.replaced(["feedback.mode=position_error"]), pin.emg.k_min),
        f"no feedback, K = {pin.emg.k_min:g}": (pin.replaced(["feedback.gain=0"]), pin.emg.k_min),
    }  # fmt: skip
    curves = {}
    for label, (scenario, gain) in cases.items():
        start = time.process_time()
        curves[label] = loop_stability(scenario, DELAYS_MS, gain=gain)
        seconds = time.process_time() - start
        onset = onset_delay(curves[label])
        on_grid = next((d for d in STUDY_GRID_MS if onset is not None and d >= onset), None)
        print(f"{label}: first unstable delay {onset} ms (on the study's grid: {on_grid} ms; "
              f"simulated: {SIMULATED_ONSET_MS if label.startswith('force') else 'never'}); "
              f"{seconds:.1f} s CPU for {len(DELAYS_MS)} delays")  # fmt: skip
    print("delay (ms) | " + " | ".join(curves))
    for row, delay in enumerate(DELAYS_MS):
        cells = [f"{results[row].spectral_radius:.5f} ({results[row].frequency_hz:.1f} Hz)"
                 for results in curves.values()]  # fmt: skip
        print(f"{delay} | " + " | ".join(cells))
    if args.figure:
        from hemg_drake.viz.figures import plot_loop_stability, save_figure

        figure = plot_loop_stability(
            curves, simulated_onset_ms=SIMULATED_ONSET_MS,
            title="cotter pin: the teleoperation loop about a hold, linearised",
        )  # fmt: skip
        save_figure(figure, args.figure)
        print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
