"""The foundation's demo: the arm moves through joint-space waypoints, recorded as a replay.

Diagram: two ``TrajectorySource`` (q_d(t) and its derivative) -> the slave station driven by
joint references (its ``VariableGainPd`` at a fixed K with gravity compensation -> the arm's
``MultibodyPlant``, 1 ms step, in free space); with a ``visualization`` the station is shown
in Meshcat, and :func:`hemg_drake.viz.recording.record_arm_demo` writes its replay.
``benchmarks/bench_arm.py`` times it; ``hemg-drake demo`` is the full pipeline
(:mod:`hemg_drake.pipeline`), not this tour.
"""

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from hemg_drake.control.pd import MAX_TIME_STEP
from hemg_drake.diagrams.station import make_slave_station
from hemg_drake.robots.baxter import HOME_POSITIONS
from hemg_drake.scenario import Scenario

# Joint-space waypoints (rad, s0 ... w2), visited at equal intervals: from home, reach
# forward and low, swing out to the side with the elbow twisted, lift, and return home.
WAYPOINTS = np.array(
    [
        HOME_POSITIONS,
        [0.35, -0.2, 0.3, 1.2, -0.4, 0.9, 0.5],
        [-0.6, -0.8, -0.5, 1.6, 0.6, 1.0, -0.6],
        [-0.2, -1.1, 0.2, 0.6, 0.0, 0.4, 0.0],
        HOME_POSITIONS,
    ]
)


def waypoint_trajectory(waypoints, duration):
    """A C2 cubic spline through ``waypoints`` at equal intervals, at rest at both ends.

    Parameters
    ----------
    waypoints : array, shape (n_points, 7), rad; n_points >= 2.
    duration : float, s, time of the last waypoint.

    Returns
    -------
    PiecewisePolynomial, q_d(t) with values of shape (7, 1).
    """
    waypoints = np.asarray(waypoints, dtype=float)
    if waypoints.ndim != 2 or waypoints.shape[0] < 2 or not np.all(np.isfinite(waypoints)):
        raise ValueError(
            f"waypoints must be finite, shape (n_points >= 2, n_joints), got {waypoints.shape}"
        )
    times = np.linspace(0.0, duration, waypoints.shape[0])
    return PiecewisePolynomial.CubicWithContinuousSecondDerivatives(
        times, waypoints.T, np.zeros(waypoints.shape[1]), np.zeros(waypoints.shape[1])
    )


def build_arm_demo(*, duration, time_step=MAX_TIME_STEP, gain=50.0, visualization=None):
    """Build the demo diagram on the slave station (free space, joint references); the arm
    starts at rest at home, the first waypoint.

    Parameters
    ----------
    duration : float, s, length of the waypoint tour.
    time_step : float, s, plant step (<= ``MAX_TIME_STEP``).
    gain : float, the PD's K (Table I: 50).
    visualization : Visualization, optional; shows the station in its Meshcat.

    Returns
    -------
    diagram, plant, arm (BaxterArm), trajectory (PiecewisePolynomial q_d(t)).
    """
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be a positive number of seconds, got {duration}")
    if not (0 < time_step <= MAX_TIME_STEP):
        raise ValueError(
            f"time_step must be in (0, {MAX_TIME_STEP}] s (the PD is tuned for it), got {time_step}"
        )
    scenario = Scenario().replaced([f"plant.time_step={time_step}"], source="build_arm_demo")
    station = make_slave_station(
        scenario, q0=HOME_POSITIONS, reference="joints", scene=False, visualization=visualization
    )
    builder = DiagramBuilder()
    slave = builder.AddSystem(station.diagram)
    trajectory = waypoint_trajectory(WAYPOINTS, duration)
    q_desired = builder.AddNamedSystem("q_desired", TrajectorySource(trajectory))
    v_desired = builder.AddNamedSystem("v_desired", TrajectorySource(trajectory.MakeDerivative()))
    constant = builder.AddNamedSystem("gain", ConstantVectorSource([float(gain)]))
    builder.Connect(q_desired.get_output_port(), slave.GetInputPort("q_desired"))
    builder.Connect(v_desired.get_output_port(), slave.GetInputPort("v_desired"))
    builder.Connect(constant.get_output_port(), slave.GetInputPort("gain"))
    diagram = builder.Build()
    diagram.set_name("arm_demo")
    return diagram, station.plant, station.arm, trajectory

