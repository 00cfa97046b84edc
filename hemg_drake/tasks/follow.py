"""Follow a task plan with the slave alone: plan -> CLIK -> PD at a fixed gain -> plant.

No operator, master or EMG: the tool-point reference is the plan itself. This is how a scene
is checked and tuned (does a constant gain K pull the pin? does the pen draw the strokes?),
by tests, benchmarks and ``docs/tasks.md``; the teleoperated diagram is
``hemg_drake.diagrams.demonstration``.
"""

import numpy as np
from pydrake.trajectories import PiecewisePolynomial
from pydrake.systems.primitives import TrajectorySource

from hemg_drake.control.clik import Clik
from hemg_drake.control.pd import VariableGainPd
from hemg_drake._validate import as_scalar


def add_plan_follower(builder, *, plant, arm, plan, gain, sample_period=0.005):
    """Drive the arm along ``plan.position(t)`` through CLIK and a constant-gain PD.

    The plan is sampled every ``sample_period`` into a piecewise-linear ``TrajectorySource``
    (its minimum-jerk segments are smooth, so linear interpolation at 5 ms is within a few
    micrometres of the exact curve), which feeds ``Clik.p_WE_desired``; the PD drives the
    arm's actuation input. Call after ``plant.Finalize()``.

    Parameters
    ----------
    builder : DiagramBuilder holding ``plant``.
    plant : MultibodyPlant, finalized, discrete.
    arm : BaxterArm.
    plan : TaskPlan, tool-point waypoints in W.
    gain : float, the PD's K (constant).
    sample_period : float, s.

    Returns
    -------
    (Clik, VariableGainPd), named ``clik`` and ``pd`` in the builder.
    """
    sample_period = as_scalar("sample_period", sample_period)
    count = int(np.ceil((plan.end_time - plan.start_time) / sample_period)) + 1
    times = np.linspace(plan.start_time, plan.end_time, count)
    trajectory = PiecewisePolynomial.FirstOrderHold(times, plan.position(times).T)
    source = builder.AddNamedSystem("plan", TrajectorySource(trajectory))
    clik = builder.AddNamedSystem(
        "clik", Clik(plant=plant, model_instance=arm.model_instance, frame_E=arm.tool_frame)
    )
    pd = builder.AddNamedSystem("pd", VariableGainPd(plant=plant, arm=arm, gain=gain))
    arm_state = plant.get_state_output_port(arm.model_instance)
    builder.Connect(source.get_output_port(), clik.GetInputPort("p_WE_desired"))
    builder.Connect(arm_state, clik.GetInputPort("state"))
    builder.Connect(arm_state, pd.state_input)
    builder.Connect(clik.GetOutputPort("q_desired"), pd.q_desired_input)
    builder.Connect(clik.GetOutputPort("v_desired"), pd.v_desired_input)
    builder.Connect(pd.torque_output, plant.get_actuation_input_port(arm.model_instance))
    return clik, pd
