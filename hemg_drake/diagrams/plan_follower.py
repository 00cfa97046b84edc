"""Follow a task plan with the slave alone: plan -> station (CLIK -> PD at a fixed gain).

No operator, master or EMG: the tool-point reference is the plan itself. This is how a scene
is checked and tuned (does a constant gain K pull the pin? does the pen draw the strokes?),
by tests, benchmarks and ``docs/tasks.md``, on the same station and plant configuration as
every scenario; the teleoperated diagram is :mod:`hemg_drake.diagrams.demonstration`.
"""

import dataclasses as dc

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from hemg_drake._validate import as_scalar
from hemg_drake.diagrams.built import StationDiagram
from hemg_drake.diagrams.station import make_slave_station


@dc.dataclass(frozen=True, eq=False)
class PlanFollower(StationDiagram):
    """A built plan-following diagram: ``diagram`` (subsystems ``plan``, ``gain``,
    ``station``), the ``station`` (SlaveStation; ``plant`` and ``scene`` are its) and the
    ``plan`` it follows (TaskPlan)."""

    plan: object


def build_plan_follower(scenario, *, gain, plan=None, sample_period=0.005, visualization=None):
    """Drive the scenario's station along ``plan.position(t)`` at a constant gain K.

    The plan is sampled every ``sample_period`` into a piecewise-linear ``TrajectorySource``
    (its minimum-jerk segments are smooth, so linear interpolation at 5 ms is within a few
    micrometres of the exact curve), which feeds the station's ``p_WE_desired``; the arm
    starts at rest on the plan's first point.

    Parameters
    ----------
    scenario : Scenario, the task, its scene and the plant.
    gain : float, the PD's K (constant).
    plan : TaskPlan, optional; default ``scenario.task_plan()``.
    sample_period : float, s.
    visualization : Visualization, optional; shows the station in its Meshcat.

    Returns
    -------
    PlanFollower; ``diagram`` exports the station's outputs under their own names.
    """
    sample_period = as_scalar("sample_period", sample_period)
    gain = as_scalar("gain", gain)
    plan = scenario.task_plan() if plan is None else plan
    count = int(np.ceil((plan.end_time - plan.start_time) / sample_period)) + 1
    times = np.linspace(plan.start_time, plan.end_time, count)
    trajectory = PiecewisePolynomial.FirstOrderHold(times, plan.position(times).T)

    builder = DiagramBuilder()
    station = make_slave_station(scenario, start=plan.points[0], visualization=visualization)
    slave = builder.AddSystem(station.diagram)
    source = builder.AddNamedSystem("plan", TrajectorySource(trajectory))
    constant = builder.AddNamedSystem("gain", ConstantVectorSource([gain]))
    builder.Connect(source.get_output_port(), slave.GetInputPort("p_WE_desired"))
    builder.Connect(constant.get_output_port(), slave.GetInputPort("gain"))
    for name in ("p_WE", "v_WE", "f_WE", "arm_state", "q_desired"):
        builder.ExportOutput(slave.GetOutputPort(name), name)
    diagram = builder.Build()
    diagram.set_name("plan_follower")
    return PlanFollower(diagram=diagram, station=station, plan=plan)
