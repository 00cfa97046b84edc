"""Cost of the robot-free teleoperation loop at the 1 kHz haptic rate.

Prints, for 10 s of simulated time, the wall time and real-time factor of
HapticMaster + SimulatedOperator + WorkspaceMap + ForceFeedback (force mode, fed a
constant slave force) in one diagram, without and with a 20-sample transport delay, and
the per-call cost of the numpy twins that those systems run every millisecond.
"""

import time
import timeit

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from hemg_drake.tasks.plan import TaskPlan
from hemg_drake.teleop.feedback import ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMap, WorkspaceMapping
from hemg_drake.teleop.master import HapticMaster, MasterDynamics
from hemg_drake.teleop.operator import OperatorModel, SimulatedOperator

SIMULATED_SECONDS = 10.0
MAPPING = WorkspaceMapping(scale=3.0, p_WMo=[0.7, -0.2, 0.25])
PLAN = TaskPlan(
    times=np.linspace(0.0, SIMULATED_SECONDS, 11),
    points=[[0.7 + 0.05 * (i % 2), -0.2 - 0.01 * i, 0.25] for i in range(11)],
    kinds=["free", "forceful"] * 5,
)


def build_loop(delay_steps):
    builder = DiagramBuilder()
    master = builder.AddSystem(HapticMaster(p_MS_initial=MAPPING.slave_to_master(PLAN.points[0])))
    operator = builder.AddSystem(SimulatedOperator(plan=PLAN, mapping=MAPPING))
    workspace_map = builder.AddSystem(WorkspaceMap(mapping=MAPPING, delay_steps=delay_steps))
    feedback = builder.AddSystem(ForceFeedback(mapping=MAPPING))
    slave_force = builder.AddSystem(ConstantVectorSource([0.0, 0.0, -2.0]))
    builder.Connect(slave_force.get_output_port(), feedback.GetInputPort("f_WE"))
    builder.Connect(feedback.GetOutputPort("motor_force"), master.GetInputPort("motor_force"))
    builder.Connect(feedback.GetOutputPort("motor_force"), operator.GetInputPort("feedback_force"))
    builder.Connect(operator.GetOutputPort("hand_force"), master.GetInputPort("hand_force"))
    for name in ("p_MS", "v_MS"):
        builder.Connect(master.GetOutputPort(name), operator.GetInputPort(name))
        builder.Connect(master.GetOutputPort(name), workspace_map.GetInputPort(name))
    # The slave side (CLIK) would read these once per step: do the same here.
    builder.ExportOutput(workspace_map.GetOutputPort("p_WE_desired"), "p_WE_desired")
    return builder.Build()


def time_loop(delay_steps):
    diagram = build_loop(delay_steps)
    simulator = Simulator(diagram)
    simulator.Initialize()
    output = diagram.GetOutputPort("p_WE_desired")
    start = time.perf_counter()
    for k in range(1, int(SIMULATED_SECONDS * 100) + 1):
        simulator.AdvanceTo(k * 0.01)  # read the map at the 100 Hz logging rate
        output.Eval(simulator.get_context())
    return time.perf_counter() - start


def per_call_microseconds(function, number=20000):
    return timeit.timeit(function, number=number) / number * 1e6


def main():
    print(f"teleop loop (master, operator, map, feedback), {SIMULATED_SECONDS:.0f} s at 1 kHz")
    for delay_steps in (0, 20):
        wall = time_loop(delay_steps)
        print(
            f"  delay {delay_steps:2d} samples: {wall:.2f} s wall, "
            f"real-time factor {SIMULATED_SECONDS / wall:.1f}x, "
            f"{wall / SIMULATED_SECONDS * 1e3:.0f} us per 1 ms step"
        )
    dynamics = MasterDynamics()
    model = OperatorModel(plan=PLAN, mapping=MAPPING)
    p, v, f = np.zeros(3), np.zeros(3), np.array([0.1, -0.2, 0.3])
    print("numpy twins, per call:")
    calls = {
        "MasterDynamics.step": lambda: dynamics.step(p, v, f, f),
        "OperatorModel.hand_force": lambda: model.hand_force(3.3, p, v),
        "OperatorModel.activation_step": lambda: model.activation_step(3.3, 0.1, f),
        "TaskPlan.position (scalar t)": lambda: PLAN.position(3.3),
    }
    for name, call in calls.items():
        print(f"  {name:31s} {per_call_microseconds(call):5.1f} us")


if __name__ == "__main__":
    main()
