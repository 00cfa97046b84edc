"""solve_tool_point_ik: Drake's InverseKinematics puts the tool point where it is asked."""

import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import DiagramBuilder

from hemg_drake.control.ik import solve_tool_point_ik
from hemg_drake.robots.baxter import add_baxter_arm
from hemg_drake.tasks.cotter_pin import add_cotter_pin_scene

DOWN = np.array([0.0, 0.0, -1.0])
PEN_AXIS_E = np.array([0.0, 0.0, 1.0])  # the tool frame's z: out of the hand, to the tip


@pytest.fixture(scope="module")
def pin_plant():
    """The arm with the cotter-pin scene in the plant (the pin's slide joint is not the arm's)."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    arm = add_baxter_arm(plant)
    add_cotter_pin_scene(plant, arm)
    plant.Finalize()
    assert plant.num_positions() > plant.num_positions(arm.model_instance)
    return plant, arm


def _tool_pose(plant, arm, q):
    """X_WE by forward kinematics on a fresh context, the scene at its defaults."""
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, arm.model_instance, q)
    return arm.tool_frame.CalcPoseInWorld(context)


TARGETS = [
    [0.64, -0.84, 0.12],  # above the default scenes
    [0.60, -0.70, 0.09],  # on a sheet moved toward the robot
    [0.75, -0.50, 0.30],
    [0.40, -0.90, -0.10],
]


@pytest.mark.parametrize("p_WE", TARGETS)
def test_reaches_the_point_within_the_limits(pin_plant, p_WE):
    plant, arm = pin_plant
    q = solve_tool_point_ik(plant, arm, p_WE)
    assert q.shape == (7,)
    np.testing.assert_allclose(_tool_pose(plant, arm, q).translation(), p_WE, rtol=0, atol=1e-6)
    assert np.all(q >= arm.position_lower) and np.all(q <= arm.position_upper)
    # Deterministic: the same call gives the same numbers.
    np.testing.assert_array_equal(solve_tool_point_ik(plant, arm, p_WE), q)


def test_stays_near_the_guess():
    """Of the arm's many solutions, the one nearest the guess: a guess that is itself a
    solution comes back (to the solver's tolerance)."""
    plant = MultibodyPlant(1e-3)
    arm = add_baxter_arm(plant)
    plant.Finalize()
    q_guess = np.array([0.3, -0.3, 0.2, 1.0, -0.2, 0.8, 0.1])
    p_WE = _tool_pose(plant, arm, q_guess).translation()
    q = solve_tool_point_ik(plant, arm, p_WE, q_guess=q_guess)
    np.testing.assert_allclose(q, q_guess, atol=1e-5)
    # From home instead, another solution, nearer home than q_guess is ...
    q_home = solve_tool_point_ik(plant, arm, p_WE)
    assert np.linalg.norm(q_home - arm.home_positions) < np.linalg.norm(q_guess - arm.home_positions)
    # ... and the nearest locally: q - home is normal to the solution set {q : p_WE(q) = p},
    # i.e. in the row space of the tool point's Jacobian (the Lagrange condition; no joint
    # limit is active here).
    assert np.all(q_home > arm.position_lower + 0.05) and np.all(q_home < arm.position_upper - 0.05)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, arm.model_instance, q_home)
    W = plant.world_frame()
    J = plant.CalcJacobianTranslationalVelocity(
        context, JacobianWrtVariable.kQDot, arm.tool_frame, np.zeros(3), W, W
    )
    step = q_home - arm.home_positions
    in_row_space = J.T @ np.linalg.lstsq(J.T, step, rcond=None)[0]
    assert np.linalg.norm(step) > 0.1
    assert np.linalg.norm(step - in_row_space) < 1e-5 * np.linalg.norm(step)


@pytest.mark.parametrize("degrees", [1.0, 5.0])
def test_axis_constraint_holds(pin_plant, degrees):
    plant, arm = pin_plant
    p_WE = [0.60, -0.70, 0.09]
    tolerance = np.radians(degrees)
    free = _tool_pose(plant, arm, solve_tool_point_ik(plant, arm, p_WE))
    assert np.arccos(-free.rotation().matrix()[2, 2]) > np.radians(10.0)  # tilted without it
    q = solve_tool_point_ik(
        plant, arm, p_WE, axis_E=PEN_AXIS_E, axis_W=DOWN, angle_tolerance=tolerance
    )
    X_WE = _tool_pose(plant, arm, q)
    np.testing.assert_allclose(X_WE.translation(), p_WE, rtol=0, atol=1e-6)
    angle = np.arccos(np.clip(X_WE.rotation().matrix()[:, 2] @ DOWN, -1.0, 1.0))
    assert angle <= tolerance + 1e-6
    assert np.all(q >= arm.position_lower) and np.all(q <= arm.position_upper)


def test_out_of_reach_names_the_point(pin_plant):
    plant, arm = pin_plant
    with pytest.raises(ValueError, match=r"p_WE = \[3.0, -0.8, 0.1\] is out of the arm's reach"):
        solve_tool_point_ik(plant, arm, [3.0, -0.8, 0.1])
    # Reachable, but not with the pen straight down (far out at the side, beyond the arm's
    # reach with a vertical pen).
    with pytest.raises(ValueError, match="with axis_E .* out of the arm's reach"):
        solve_tool_point_ik(
            plant, arm, [0.70, -0.93, 0.087], axis_E=PEN_AXIS_E, axis_W=DOWN,
            angle_tolerance=np.radians(5.0),
        )


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(p_WE=[0.6, -0.7]), "p_WE must have shape"),
        (dict(p_WE=[0.6, np.nan, 0.1]), "p_WE must be finite"),
        (dict(axis_E=[0, 0, 1]), "both axis_E and axis_W"),
        (dict(axis_E=[0, 0, 0], axis_W=DOWN), "axis_E must be a nonzero direction"),
        (dict(axis_E=PEN_AXIS_E, axis_W=DOWN, angle_tolerance=-0.1), "angle_tolerance"),
        (dict(angle_tolerance=4.0), "angle_tolerance must be <= pi"),
        (dict(q_guess=np.zeros(6)), "q_guess must have shape"),
    ],
)
def test_bad_arguments_are_named(pin_plant, kwargs, message):
    plant, arm = pin_plant
    kwargs = {"p_WE": [0.6, -0.7, 0.1], **kwargs}
    with pytest.raises(ValueError, match=message):
        solve_tool_point_ik(plant, arm, **kwargs)


def test_needs_a_finalized_plant():
    plant = MultibodyPlant(1e-3)
    arm = add_baxter_arm(plant)
    with pytest.raises(ValueError, match="finalized plant"):
        solve_tool_point_ik(plant, arm, [0.6, -0.7, 0.1])


def test_default_tolerance_reaches_the_default_sheets_start(pin_plant):
    """Above the default sheet a vertical pen comes no closer than 0.94 deg: the default
    tolerance (0.05 rad) still gives a start there, within it."""
    plant, arm = pin_plant
    p_WE = [0.64, -0.84, 0.12]
    q = solve_tool_point_ik(plant, arm, p_WE, axis_E=PEN_AXIS_E, axis_W=DOWN)
    X_WE = _tool_pose(plant, arm, q)
    np.testing.assert_allclose(X_WE.translation(), p_WE, rtol=0, atol=1e-6)
    assert np.arccos(X_WE.rotation().matrix()[:, 2] @ DOWN) <= 0.05 + 1e-6
    with pytest.raises(ValueError, match="out of the arm's reach"):
        solve_tool_point_ik(plant, arm, p_WE, axis_E=PEN_AXIS_E, axis_W=DOWN, angle_tolerance=0.01)
