"""The waypoint demo diagram: the arm follows the tour under VariableGainPd."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from hemg_drake.diagrams.arm_demo import WAYPOINTS, build_arm_demo, waypoint_trajectory
from hemg_drake.viz.recording import record_arm_demo


def test_waypoints_are_within_limits():
    _, _, arm, _ = build_arm_demo(duration=1.0)
    assert WAYPOINTS.shape[1] == 7
    assert np.all((arm.position_lower < WAYPOINTS) & (WAYPOINTS < arm.position_upper))


def test_the_tour_drives_the_station_by_joint_references():
    diagram, plant, arm, trajectory = build_arm_demo(duration=1.0, gain=80.0)
    station = diagram.GetSubsystemByName("station")
    assert not station.HasSubsystemNamed("clik") and station.HasSubsystemNamed("pd")
    q_desired = diagram.GetSubsystemByName("q_desired").get_output_port()
    assert diagram.AreConnected(q_desired, station.GetInputPort("q_desired"))
    v_desired = diagram.GetSubsystemByName("v_desired").get_output_port()
    assert diagram.AreConnected(v_desired, station.GetInputPort("v_desired"))
    # Free space, at rest at home (the first waypoint), time 0: building simulated nothing.
    context = diagram.CreateDefaultContext()
    assert context.get_time() == 0.0 and plant.num_velocities() == 7
    np.testing.assert_array_equal(plant.GetPositions(plant.GetMyContextFromRoot(context)), WAYPOINTS[0])
    pd = station.GetSubsystemByName("pd")
    assert pd.gain_input.Eval(pd.GetMyContextFromRoot(context))[0] == 80.0
    context.SetTime(0.5)
    np.testing.assert_array_equal(
        station.GetInputPort("v_desired").Eval(station.GetMyContextFromRoot(context)),
        trajectory.MakeDerivative().value(0.5).ravel(),
    )


def test_trajectory_passes_waypoints_at_rest_ends():
    trajectory = waypoint_trajectory(WAYPOINTS, 4.0)
    times = np.linspace(0.0, 4.0, len(WAYPOINTS))
    for t, q in zip(times, WAYPOINTS):
        np.testing.assert_allclose(trajectory.value(t).ravel(), q, atol=1e-12)
    velocity = trajectory.MakeDerivative()
    np.testing.assert_allclose(velocity.value(0.0).ravel(), 0.0, atol=1e-12)
    np.testing.assert_allclose(velocity.value(4.0).ravel(), 0.0, atol=1e-12)


def test_arm_follows_the_tour():
    duration = 4.0
    diagram, plant, arm, trajectory = build_arm_demo(duration=duration)
    simulator = Simulator(diagram)
    plant_context = plant.GetMyContextFromRoot(simulator.get_context())
    errors, travel = [], []
    for t in np.linspace(0.25, duration, 16):
        simulator.AdvanceTo(t)
        q = plant.GetPositions(plant_context, arm.model_instance)
        errors.append(np.max(np.abs(q - trajectory.value(t).ravel())))
        travel.append(np.max(np.abs(q - WAYPOINTS[0])))
    # The arm really tours (joints swing by more than 0.5 rad) and lags by less than 0.2 rad.
    assert max(travel) > 0.5
    assert max(errors) < 0.2
    simulator.AdvanceTo(duration + 1.0)  # the last waypoint is held
    q = plant.GetPositions(plant_context, arm.model_instance)
    np.testing.assert_allclose(q, WAYPOINTS[-1], atol=1e-3)


def test_run_writes_replay(tmp_path):
    path = record_arm_demo(tmp_path / "out", duration=0.2)
    assert path == tmp_path / "out" / "replay.html"
    assert "<html" in path.read_text(encoding="utf-8")[:5000].lower()


@pytest.mark.parametrize(
    "kwargs, message",
    [({"duration": 0.0}, "duration"), ({"duration": float("nan")}, "duration"),
     ({"duration": 1.0, "time_step": 1e-2}, "time_step")],
)
def test_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        build_arm_demo(**kwargs)


def test_bad_waypoints():
    with pytest.raises(ValueError, match="waypoints"):
        waypoint_trajectory(np.zeros((1, 7)), 1.0)
