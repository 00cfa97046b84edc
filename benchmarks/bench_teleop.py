"""Cost of the robot-free teleoperation loop at the 1 kHz haptic rate.

Prints, for 10 s of simulated time, the CPU time per 1 ms step and real-time factor of
HapticMaster + SimulatedOperator + WorkspaceMap + ForceFeedback (force mode, fed a constant
slave force) in one diagram, without and with a 20-sample transport delay each way (Drake's
``DiscreteTimeDelay`` in the map and in the feedback) and with the passivity controller;
then the per-call cost of each Python system's 1 kHz work, evaluated through Drake from a
Context (the master's discrete update, the operator's hand force, the feedback's force).
Process CPU time (median and best of 5 runs, in turn): on the shared machine, other jobs'
load moves wall time by up to 2x.
"""

import time
import timeit

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from hemg_drake.tasks.plan import TaskPlan
from hemg_drake.teleop.config import FeedbackConfig, MappingConfig, MasterConfig, OperatorConfig
from hemg_drake.teleop.feedback import ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMap, WorkspaceMapping
from hemg_drake.teleop.master import HapticMaster
from hemg_drake.teleop.operator import SimulatedOperator

SIMULATED_SECONDS = 10.0
PERIOD = MasterConfig().period
MAPPING = WorkspaceMapping(scale=3.0, p_WMo=[0.7, -0.2, 0.25])
PLAN = TaskPlan(
    times=np.linspace(0.0, SIMULATED_SECONDS, 11),
    points=[[0.7 + 0.05 * (i % 2), -0.2 - 0.01 * i, 0.25] for i in range(11)],
    kinds=["free", "forceful"] * 5,
)


def build_loop(delay_steps, passivity="none"):
    builder = DiagramBuilder()
    master = builder.AddSystem(HapticMaster(p_MS_initial=MAPPING.slave_to_master(PLAN.points[0])))
    operator = builder.AddSystem(SimulatedOperator(plan=PLAN, mapping=MAPPING))
    workspace_map = builder.AddSystem(
        WorkspaceMap(mapping=MAPPING, period=PERIOD, config=MappingConfig(delay_steps=delay_steps))
    )
    feedback_config = FeedbackConfig(delay_steps=delay_steps, passivity=passivity)
    feedback = builder.AddSystem(
        ForceFeedback(mapping=MAPPING, period=PERIOD, config=feedback_config)
    )
    slave_force = builder.AddSystem(ConstantVectorSource([0.0, 0.0, -2.0]))
    builder.Connect(slave_force.get_output_port(), feedback.GetInputPort("f_WE"))
    if passivity != "none":
        builder.Connect(master.GetOutputPort("v_MS"), feedback.GetInputPort("v_MS"))
    builder.Connect(feedback.GetOutputPort("motor_force"), master.GetInputPort("motor_force"))
    builder.Connect(feedback.GetOutputPort("motor_force"), operator.GetInputPort("feedback_force"))
    builder.Connect(operator.GetOutputPort("hand_force"), master.GetInputPort("hand_force"))
    for name in ("p_MS", "v_MS"):
        builder.Connect(master.GetOutputPort(name), operator.GetInputPort(name))
        builder.Connect(master.GetOutputPort(name), workspace_map.GetInputPort(name))
    builder.ExportOutput(workspace_map.GetOutputPort("p_WE_desired"), "p_WE_desired")
    return builder.Build()


def time_loop(delay_steps, passivity="none"):
    """CPU seconds of ``SIMULATED_SECONDS``, the map read at the 100 Hz logging rate."""
    diagram = build_loop(delay_steps, passivity)
    simulator = Simulator(diagram)
    simulator.Initialize()
    output = diagram.GetOutputPort("p_WE_desired")
    start = time.process_time()
    for k in range(1, int(SIMULATED_SECONDS * 100) + 1):
        simulator.AdvanceTo(k * 0.01)
        output.Eval(simulator.get_context())
    return time.process_time() - start


def per_call_microseconds(function, number=20000):
    """CPU time per call (us), best of 3."""
    timer = timeit.Timer(function, timer=time.process_time)
    return min(timer.repeat(3, number)) / number * 1e6


def system_calls():
    """One 1 kHz call of each Python system, through Drake from a fixed Context: pairs of
    (what invalidates the cached result, that plus the evaluation)."""
    master = HapticMaster()
    master_context = master.CreateDefaultContext()
    for name in ("hand_force", "motor_force"):
        master.GetInputPort(name).FixValue(master_context, [0.1, -0.2, 0.3])
    operator = SimulatedOperator(plan=PLAN, mapping=MAPPING, config=OperatorConfig())
    operator_context = operator.CreateDefaultContext()
    for name in ("p_MS", "v_MS", "feedback_force"):
        operator.GetInputPort(name).FixValue(operator_context, [0.01, 0.0, -0.01])
    feedback = ForceFeedback(mapping=MAPPING, period=PERIOD)
    feedback_context = feedback.CreateDefaultContext()
    f_WE = feedback.GetInputPort("f_WE")
    hand_force = operator.GetOutputPort("hand_force")
    motor_force = feedback.GetOutputPort("motor_force")

    def touch_master():
        master_context.get_mutable_discrete_state(0)  # marks the state changed

    def touch_operator():
        operator_context.SetTime(3.3)  # invalidates the time-dependent hand force

    def touch_feedback():
        f_WE.FixValue(feedback_context, [0.0, 0.0, -2.0])

    def master_call():
        touch_master()
        master.EvalUniquePeriodicDiscreteUpdate(master_context)

    def operator_call():
        touch_operator()
        hand_force.Eval(operator_context)

    def feedback_call():
        touch_feedback()
        motor_force.Eval(feedback_context)

    return {
        "HapticMaster discrete update": (touch_master, master_call),
        "SimulatedOperator hand_force": (touch_operator, operator_call),
        "ForceFeedback motor_force": (touch_feedback, feedback_call),
    }


def main(repeats=5):
    print(f"teleop loop (master, operator, map, feedback), {SIMULATED_SECONDS:.0f} s at 1 kHz:")
    cases = {"no delay": (0, "none"), "delay 20 each way": (20, "none"),
             "delay 20, passivity tdpa": (20, "tdpa")}  # fmt: skip
    times = {name: [] for name in cases}
    for _ in range(repeats):
        for name, case in cases.items():
            times[name].append(time_loop(*case))
    for name, values in times.items():
        cpu = np.median(values)
        print(
            f"  {name:25s} {cpu / SIMULATED_SECONDS * 1e3:5.1f} us CPU per 1 ms step "
            f"(best {min(values) / SIMULATED_SECONDS * 1e3:5.1f}), "
            f"real-time factor {SIMULATED_SECONDS / cpu:.1f}x"
        )
    print("one call through Drake (less the invalidation that forces it):")
    for name, (touch, call) in system_calls().items():
        cost = per_call_microseconds(call) - per_call_microseconds(touch)
        print(f"  {name:31s} {cost:5.1f} us")


if __name__ == "__main__":
    main()
