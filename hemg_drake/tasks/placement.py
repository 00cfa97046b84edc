"""Where a task's object stands: the scene frame T, a position and a turn about world z.

Every task scene is modelled in its own frame T (the cotter pin's ring, the sheet's centre)
and placed by ``X_WT``; its plan is written in T and mapped to the world with the same pose,
so a moved scene moves everything that belongs to the task (``Scenario.scene``).
"""

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from hemg_drake._validate import as_scalar, as_vector


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


def to_world(X_WT, points_T):
    """Points (n, 3) or one point (3,) given in T, expressed in W (m)."""
    points_T = np.asarray(points_T, dtype=float)
    return (X_WT.rotation().matrix() @ points_T.T).T + X_WT.translation()
