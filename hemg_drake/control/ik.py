"""The arm's configuration that puts the tool point at a given place, by Drake's IK.

:func:`solve_tool_point_ik` poses one nonlinear program with
``pydrake.multibody.inverse_kinematics.InverseKinematics`` and solves it with
``pydrake.solvers.Solve`` (SNOPT in Drake's wheels)::

    min_q   |q_arm - q_guess|^2
    s.t.    p_WE(q) = p_WE_target                  (PositionConstraint, tool point E)
            angle(R_WE axis_E, axis_W) <= angle_tolerance      (optional)
            q_lower <= q <= q_upper                (the plant's joint limits)
            q_other = the plant's default positions (scene models: pin, table, ...)

The cost picks, among the arm's many solutions (7 joints for 3 or 5 constraints), the one
nearest the guess (by default ``arm.home_positions``), so a run starts from a familiar pose
and the same call always gives the same answer (SNOPT is deterministic from one guess).
"""

import numpy as np
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import SnoptSolver, Solve, SolverOptions

from hemg_drake._validate import as_scalar, as_vector
from hemg_drake.control.clik import unit_direction

# A reached point is within this of the target (m); beyond it the point is out of reach.
REACH_TOLERANCE = 1e-3
# SNOPT's default feasibility tolerance (1e-6, relative) leaves micrometres on the tool
# point; 1e-10 costs a few more iterations and puts it at the nanometre.
_FEASIBILITY_TOLERANCE = 1e-10


def solve_tool_point_ik(
    plant,
    arm,
    p_WE,
    *,
    axis_E=None,
    axis_W=None,
    angle_tolerance=0.05,
    q_guess=None,
):
    """The arm's joint positions that put the tool point at ``p_WE``, near ``q_guess``.

    Parameters
    ----------
    plant : MultibodyPlant, finalized, holding ``arm`` and possibly scene models (their
        positions are held at the plant's defaults).
    arm : BaxterArm; the tool point is the origin of ``arm.tool_frame``.
    p_WE : array, shape (3,), the target of the tool point in W (m).
    axis_E, axis_W : array, shape (3,), optional, together: a direction fixed in the tool
        frame (e.g. the pen's axis, its z) and the world direction it must point along (e.g.
        (0, 0, -1), down), each nonzero (normalised here).
    angle_tolerance : float, the largest angle between them (rad, >= 0), with the axes.
        The default 0.05 rad (2.9 deg) reaches the default drawing sheet's first point
        (0.64, -0.84, 0.12), where a vertical pen comes no closer than 0.94 deg; Clik's axis
        task turns the rest once running.
    q_guess : array, shape (7,), optional; the solver's start and the cost's centre (rad).
        Default ``arm.home_positions``.

    Returns
    -------
    q : array, shape (7,), rad, in ``arm.joint_names`` order, within the joint limits.

    Raises
    ------
    ValueError
        Bad arguments (naming them), or the point (with its axis) is out of reach: the
        solver fails or the tool point ends more than 1 mm from ``p_WE``.
    """
    if not plant.is_finalized():
        raise ValueError("solve_tool_point_ik needs a finalized plant")
    p_WE = as_vector("p_WE", p_WE, 3)
    if (axis_E is None) != (axis_W is None):
        raise ValueError("solve_tool_point_ik needs both axis_E and axis_W, or neither")
    angle_tolerance = as_scalar("angle_tolerance", angle_tolerance, strict=False)
    if angle_tolerance > np.pi:
        raise ValueError(f"angle_tolerance must be <= pi rad, got {angle_tolerance}")
    model = arm.model_instance
    n = plant.num_positions(model)
    q_guess = (
        np.asarray(arm.home_positions, dtype=float)
        if q_guess is None
        else as_vector("q_guess", q_guess, n)
    )

    ik = InverseKinematics(plant, with_joint_limits=True)
    q = ik.q()
    # Where the arm's positions sit among the plant's (the variables are symbolic, so the
    # plant's array helpers index a numbered array instead).
    index = np.arange(plant.num_positions(), dtype=float)
    arm_index = plant.GetPositionsFromArray(model, index).astype(int)
    other = np.setdiff1d(np.arange(plant.num_positions()), arm_index)
    q_arm = q[arm_index]
    # Everything but the arm stays where the plant puts it by default.
    q_start = plant.GetPositions(plant.CreateDefaultContext()).copy()
    if other.size:
        ik.prog().AddBoundingBoxConstraint(q_start[other], q_start[other], q[other])
    # The guess inside the limits: SNOPT starts from a feasible box point.
    lower = plant.GetPositionsFromArray(model, plant.GetPositionLowerLimits())
    upper = plant.GetPositionsFromArray(model, plant.GetPositionUpperLimits())
    q_start[arm_index] = np.clip(q_guess, lower, upper)

    world = plant.world_frame()
    ik.AddPositionConstraint(
        frameB=arm.tool_frame,
        p_BQ=np.zeros(3),
        frameA=world,
        p_AQ_lower=p_WE,
        p_AQ_upper=p_WE,
    )
    if axis_E is not None:
        axis_E = unit_direction("axis_E", axis_E)
        axis_W = unit_direction("axis_W", axis_W)
        ik.AddAngleBetweenVectorsConstraint(
            frameA=world,
            na_A=axis_W,
            frameB=arm.tool_frame,
            nb_B=axis_E,
            angle_lower=0.0,
            angle_upper=angle_tolerance,
        )
    ik.prog().AddQuadraticErrorCost(np.eye(n), q_guess, q_arm)

    options = SolverOptions()
    options.SetOption(SnoptSolver.id(), "Major feasibility tolerance", _FEASIBILITY_TOLERANCE)
    result = Solve(ik.prog(), q_start, options)
    solution = result.GetSolution(q)
    q_solution = plant.GetPositionsFromArray(model, solution)

    context = plant.CreateDefaultContext()
    plant.SetPositions(context, solution)
    X_WE = arm.tool_frame.CalcPoseInWorld(context)
    residual = float(np.linalg.norm(X_WE.translation() - p_WE))
    what = f"tool point p_WE = {p_WE.tolist()}"
    if axis_E is not None:
        what += f" with axis_E {axis_E.tolist()} along axis_W {axis_W.tolist()}"
    if not result.is_success() or residual > REACH_TOLERANCE:
        raise ValueError(
            f"{what} is out of the arm's reach ({result.get_solver_id().name()}: "
            f"{result.get_solution_result().name}, {residual:.3g} m from it)"
        )
    return np.clip(q_solution, lower, upper)
