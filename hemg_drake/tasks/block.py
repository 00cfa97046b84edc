"""An unexpected rigid block in a task's scene (``scene.block``): a world that differs from
the demonstrations' (the stiffness study, ``docs/studies.md``).

The block is a box body of its own, welded to the world at ``X_WT`` times its position in
the scene frame T, with a collision geometry (point contact, ``BlockConfig.stiffness`` and
``dissipation``) and a visual one. Nothing filters its collisions: every collision geometry
of the arm (its links, the drawing's pen tip) can hit it. Neither the plan nor the operator
knows of it. Its contact force, the force the arm puts on the environment there, is read by
a :class:`~hemg_drake.tasks.sensors.ContactForceSensor` on the block (``f_block``: the sum
of the contact forces on the block, N, in W).
"""

import dataclasses as dc

import numpy as np
from pydrake.geometry import AddContactMaterial, Box, ProximityProperties
from pydrake.math import RigidTransform
from pydrake.multibody.plant import CoulombFriction
from pydrake.multibody.tree import SpatialInertia, UnitInertia

from hemg_drake.tasks.sensors import ContactForceSensor

_BLOCK_GREY = (0.45, 0.45, 0.5, 1.0)
# Coulomb friction of the block's surface (a painted box).
_FRICTION = 0.3


@dc.dataclass(frozen=True, eq=False)
class BlockScene:
    """Handles to the block in a plant, from :func:`add_block`.

    Attributes
    ----------
    plant : MultibodyPlant
    body : RigidBody, the block (welded to the world).
    X_WB : RigidTransform, the block's centre and axes in W.
    size : array, shape (3,), its edge lengths (m).
    """

    plant: object
    body: object
    X_WB: RigidTransform
    size: np.ndarray

    def force_output_port(self, builder):
        """``f_block`` (3, N, W): the contact force on the block; adds its sensor (once,
        named ``block_force``). Call after ``plant.Finalize()``."""
        if builder.HasSubsystemNamed("block_force"):
            return builder.GetSubsystemByName("block_force").f_WE_output
        sensor = builder.AddNamedSystem(
            "block_force", ContactForceSensor(plant=self.plant, body=self.body)
        )
        builder.Connect(self.plant.get_contact_results_output_port(), sensor.contact_results_input)
        return sensor.f_WE_output


def add_block(plant, config, X_WT):
    """Add the scenario's block (a ``BlockConfig``) to ``plant``, placed in the scene frame.

    Call before ``plant.Finalize()``.

    Parameters
    ----------
    plant : MultibodyPlant, not finalized, registered with a SceneGraph.
    config : BlockConfig; an empty ``size`` adds nothing.
    X_WT : RigidTransform, the scene frame.

    Returns
    -------
    BlockScene, or None when ``config.size`` is empty.
    """
    if not config.size:
        return None
    if plant.is_finalized():
        raise ValueError("add_block must be called before plant.Finalize()")
    size = np.asarray(config.size, dtype=float)
    instance = plant.AddModelInstance("block")
    # Welded: its mass never enters the dynamics; a unit-free inertia keeps Drake content.
    body = plant.AddRigidBody(
        "block", instance, SpatialInertia(1.0, np.zeros(3), UnitInertia.SolidBox(*size))
    )
    X_WB = X_WT @ RigidTransform(np.asarray(config.position, dtype=float))
    plant.WeldFrames(plant.world_frame(), body.body_frame(), X_WB)
    properties = ProximityProperties()
    AddContactMaterial(
        dissipation=config.dissipation,
        point_stiffness=config.stiffness,
        friction=CoulombFriction(_FRICTION, _FRICTION),
        properties=properties,
    )
    shape = Box(*size)
    plant.RegisterCollisionGeometry(body, RigidTransform(), shape, "block", properties)
    plant.RegisterVisualGeometry(body, RigidTransform(), shape, "block", np.array(_BLOCK_GREY))
    return BlockScene(plant=plant, body=body, X_WB=X_WB, size=size)
