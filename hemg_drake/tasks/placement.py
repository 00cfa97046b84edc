"""Where a task's object stands: the scene frame T, a position and a turn about world z.

Every task scene is modelled in its own frame T (the cotter pin's ring, the sheet's centre)
and placed by ``X_WT``; its plan is written in T and mapped to the world with the same pose,
so a moved scene moves everything that belongs to the task (``Scenario.scene``), the
master's frame too (:func:`master_orientation`). Poses only: no plant, no system.
"""

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from hemg_drake._validate import as_scalar, as_vector

# Where each task's scene frame T stands by default (m, in W). The cotter pin's ring waits
# at the tool point p_WE of BaxterArm.home_positions, to the millimetre; the sheet's
# top-surface centre is 3 cm under it, to 3 mm.
DEFAULT_POSITIONS = {"cotter_pin": (0.642, -0.837, 0.120), "drawing": (0.64, -0.84, 0.09)}


def scene_pose(position, yaw_deg=0.0):
    """The pose X_WT of a scene frame: ``position`` (m, in W) and a yaw about world +z (deg).

    Raises
    ------
    ValueError
        ``position`` is not 3 finite numbers, or ``yaw_deg`` is not a finite number.
    """
    position = as_vector("scene position", position, 3)
    yaw = as_scalar("scene yaw_deg", yaw_deg, minimum=-np.inf, strict=False)
    return RigidTransform(RotationMatrix.MakeZRotation(np.radians(yaw)), position)


def task_scene_pose(task, scene):
    """X_WT of a task's scene (a ``SceneConfig``): its position, or the task's default, and
    its yaw."""
    return scene_pose(scene.position or DEFAULT_POSITIONS[task], scene.yaw_deg)


def checked_scene_pose(X_WT, task, *, what="scene"):
    """``X_WT``, or the task's default pose if None, checked to turn about world z only.

    Raises
    ------
    ValueError
        Not a RigidTransform, or a pose that tilts world z (``what`` names the object).
    """
    if X_WT is None:
        return scene_pose(DEFAULT_POSITIONS[task])
    if not isinstance(X_WT, RigidTransform):
        raise ValueError(f"X_WT must be a RigidTransform, got {type(X_WT).__name__}")
    if not np.allclose(X_WT.rotation().matrix()[:, 2], [0.0, 0.0, 1.0], atol=1e-9):
        raise ValueError(f"X_WT may only turn the {what} about world z (its yaw)")
    return X_WT


def master_orientation(X_WT, rpy_deg):
    """R_WM: the master frame's orientation in W, the scene's turn then ``rpy_deg`` (roll,
    pitch, yaw in degrees, M relative to T)."""
    R_TM = RotationMatrix(RollPitchYaw(np.radians(rpy_deg)))
    return X_WT.rotation() @ R_TM


def to_world(X_WT, points_T):
    """Points (n, 3) or one point (3,) given in T, expressed in W (m)."""
    points_T = np.asarray(points_T, dtype=float)
    return (X_WT.rotation().matrix() @ points_T.T).T + X_WT.translation()
