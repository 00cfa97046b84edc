"""Cost of the robot-free teleoperation loop at the 1 kHz haptic rate.

Prints, for 10 s of simulated time, the wall time and real-time factor of
HapticMaster + SimulatedOperator + WorkspaceMap + ForceFeedback (force mode, fed a
constant slave force) in one diagram, without and with a 20-sample transport delay, and
the per-call cost of the numpy twins that those systems run every millisecond.

Then the workspace map's transport delay, two ways, in CPU time per 1 ms step (median
and best of 7 runs, run in turn): ``WorkspaceMap`` (Drake's ``DiscreteTimeDelay`` inside)
and the FIFO of Python discrete state it replaced (``FifoWorkspaceMap`` below, kept as the
yardstick), each in the loop above, once with the slave reading the map at 100 Hz and once
reading both targets every 1 ms (two ``ZeroOrderHold``s at 1 kHz stand in for the CLIK).
"""

import time
import timeit

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource, ZeroOrderHold

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


class FifoWorkspaceMap(LeafSystem):
    """The delayed map as it was before DiscreteTimeDelay: a FIFO of n [p_MS; v_MS] samples
    in discrete state, shifted by a Python update every period (same outputs)."""

    def __init__(self, *, mapping, delay_steps, period=1e-3, p_MS_initial=(0.0, 0.0, 0.0)):
        LeafSystem.__init__(self)
        self.mapping = mapping
        self._p_MS_input = self.DeclareVectorInputPort("p_MS", 3)
        self._v_MS_input = self.DeclareVectorInputPort("v_MS", 3)
        at_rest = np.concatenate([p_MS_initial, np.zeros(3)])
        self.DeclareDiscreteState(np.tile(at_rest, delay_steps))
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=period, offset_sec=0.0, update=self._update
        )
        state = {self.xd_ticket()}
        self.DeclareVectorOutputPort("p_WE_desired", 3, self._calc_p, prerequisites_of_calc=state)
        self.DeclareVectorOutputPort("v_WE_desired", 3, self._calc_v, prerequisites_of_calc=state)

    def _update(self, context, discrete_state):
        fifo = context.get_discrete_state_vector().value()
        newest = np.concatenate([self._p_MS_input.Eval(context), self._v_MS_input.Eval(context)])
        if not np.all(np.isfinite(newest)):
            raise ValueError("p_MS and v_MS must be finite")
        discrete_state.set_value(np.concatenate([fifo[6:], newest]))

    def _calc_p(self, context, output):
        p_MS = context.get_discrete_state_vector().value()[0:3]
        output.SetFromVector(self.mapping.master_to_slave_floats(p_MS.tolist()))

    def _calc_v(self, context, output):
        v_MS = context.get_discrete_state_vector().value()[3:6]
        output.SetFromVector(self.mapping.velocity_to_slave(v_MS))


def build_loop(delay_steps, map_class=WorkspaceMap, read_every_step=False):
    builder = DiagramBuilder()
    master = builder.AddSystem(HapticMaster(p_MS_initial=MAPPING.slave_to_master(PLAN.points[0])))
    operator = builder.AddSystem(SimulatedOperator(plan=PLAN, mapping=MAPPING))
    workspace_map = builder.AddSystem(map_class(mapping=MAPPING, delay_steps=delay_steps))
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
    if read_every_step:
        for name in ("p_WE_desired", "v_WE_desired"):
            reader = builder.AddSystem(ZeroOrderHold(1e-3, 3))
            builder.Connect(workspace_map.GetOutputPort(name), reader.get_input_port())
    return builder.Build()


def time_loop(delay_steps, clock=time.perf_counter, **loop_options):
    diagram = build_loop(delay_steps, **loop_options)
    simulator = Simulator(diagram)
    simulator.Initialize()
    output = diagram.GetOutputPort("p_WE_desired")
    start = clock()
    for k in range(1, int(SIMULATED_SECONDS * 100) + 1):
        simulator.AdvanceTo(k * 0.01)  # read the map at the 100 Hz logging rate
        output.Eval(simulator.get_context())
    return clock() - start


def compare_delays(repeats=7):
    """CPU time per 1 ms step (us) of each map, run in turn ``repeats`` times.

    Process CPU time rather than wall time: on the shared machine, other jobs' load moves
    the wall time of a run by up to 2x; the CPU time of this process much less.
    """
    cases = {
        "no delay (memoryless map)": dict(delay_steps=0),
        "delay 20, DiscreteTimeDelay": dict(delay_steps=20),
        "delay 20, Python FIFO": dict(delay_steps=20, map_class=FifoWorkspaceMap),
    }
    for read_every_step in (False, True):
        reads = "every 1 ms" if read_every_step else "at 100 Hz"
        print(f"workspace map delay, slave reading the map {reads} ({repeats} runs):")
        times = {name: [] for name in cases}
        for _ in range(repeats):
            for name, options in cases.items():
                cpu = time_loop(
                    read_every_step=read_every_step, clock=time.process_time, **options
                )
                times[name].append(cpu / SIMULATED_SECONDS * 1e3)
        for name, values in times.items():
            print(
                f"  {name:29s} {np.median(values):5.1f} us CPU per 1 ms step "
                f"(best {min(values):5.1f})"
            )


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
    compare_delays()


if __name__ == "__main__":
    main()
