"""Delayed force feedback with and without the time-domain passivity controller.

The loop of ``tests/teleop/test_feedback.py``: the Touch X stylus held by a hand (300 N/m,
5 N s/m, the simulated operator's impedance), the slave following it through a
``WorkspaceMap`` delay of n samples into a stiff environment (a 500 N/m spring in W), the
spring's force fed back (``ForceFeedback``, mode "force", gain 1) through another n
samples. The stylus starts 5 mm off the spring's rest. Prints, per one-way delay, the
largest stylus excursion over the last second of 3 s, plain and with
``passivity="tdpa"``, and with ``--figure PATH`` plots it (docs/img/study_delay_loop.png).
"""

import argparse

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Adder, ConstantVectorSource, MatrixGain

from hemg_drake.teleop.feedback import ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMap, WorkspaceMapping
from hemg_drake.teleop.master import HapticMaster

DELAYS_MS = (0, 2, 5, 10, 20, 50, 100, 200)
DURATION = 3.0


def excursion(delay_steps, passivity, k_env=500.0):
    """Largest |x| of the stylus (m) over the last second, and the observer's least E (J)."""
    mapping = WorkspaceMapping(scale=2.0)
    builder = DiagramBuilder()
    master = builder.AddSystem(HapticMaster(p_MS_initial=[0.005, 0.0, 0.0]))
    channel = builder.AddSystem(WorkspaceMap(mapping=mapping, delay_steps=delay_steps))
    feedback = builder.AddSystem(ForceFeedback(
        mapping=mapping, delay_steps=delay_steps, passivity=passivity, peak_force=1e3
    ))  # fmt: skip
    for name in ("p_MS", "v_MS"):
        builder.Connect(master.GetOutputPort(name), channel.GetInputPort(name))
    spring = builder.AddSystem(MatrixGain(-k_env * np.eye(3)))
    rest = builder.AddSystem(ConstantVectorSource(k_env * mapping.master_to_slave(np.zeros(3))))
    total = builder.AddSystem(Adder(2, 3))
    builder.Connect(channel.GetOutputPort("p_WE_desired"), spring.get_input_port())
    builder.Connect(spring.get_output_port(), total.get_input_port(0))
    builder.Connect(rest.get_output_port(), total.get_input_port(1))
    builder.Connect(total.get_output_port(), feedback.GetInputPort("f_WE"))
    if passivity != "none":
        builder.Connect(master.GetOutputPort("v_MS"), feedback.GetInputPort("v_MS"))
    builder.Connect(feedback.GetOutputPort("motor_force"), master.GetInputPort("motor_force"))
    hand = builder.AddSystem(MatrixGain(np.hstack([-300.0 * np.eye(3), -5.0 * np.eye(3)])))
    builder.Connect(master.GetOutputPort("state"), hand.get_input_port())
    builder.Connect(hand.get_output_port(), master.GetInputPort("hand_force"))
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    x, energy = [], []
    for t in np.arange(0.01, DURATION + 1e-9, 0.01):
        simulator.AdvanceTo(t)
        p_MS = master.GetOutputPort("p_MS").Eval(master.GetMyContextFromRoot(context))
        x.append(abs(p_MS[0]))
        if feedback.stateful:
            energy.append(feedback.energy(feedback.GetMyContextFromRoot(context)))
    return max(x[-100:]), min(energy) if energy else 0.0


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
