"""The drawing task (the paper's Fig. 9-11): a pen on the slave draws three strokes on an A4 sheet.

Scene (``models/drawing.sdf``, primitives only): a table in front of the robot with an A4
sheet (210 mm along the scene frame's x, 297 mm along its y) whose top surface centre is
the origin of the scene frame T (``X_WT``: ``scene.position`` and ``scene.yaw_deg`` of a
scenario; by default ``DEFAULT_POSITION``, unturned). :func:`add_drawing_scene` also gives the arm a **pen**: a
collision sphere of radius ``pen_radius`` on ``right_hand`` whose lowest point is the
``right_tool`` point (so the tool point E, which CLIK drives, is the pen's tip P), and a
green visual body along the hand's z axis.

Contact (pen tip on paper): compliant point contact, solved by the plant's discrete SAP
solver (1 ms, Drake's default ``lagged`` approximation, which uses Hunt-Crossley
dissipation). The sheet is nearly rigid (1e6 N/m, in the model file); Drake combines point
stiffnesses in series, so the contact's stiffness is close to the pen's ``pen_stiffness``
(1e4 N/m: 1 N presses the tip 0.1 mm) and its dissipation the pen's ``pen_dissipation``
(s/m); Coulomb friction ``pen_friction`` (0.2 on both, a felt tip on paper).

The contact model is chosen explicitly: the plant must use ``point`` contact
(``MultibodyPlantConfig.contact_model: point``, the scenarios' default), and
:func:`add_drawing_scene` refuses any other. Why point contact: the pen's tip is a 3 mm
sphere pressed 0.1 mm into a sheet; one point with one stiffness per geometry is the model
whose parameters (``pen_stiffness``, the force per depth a pen tip shows) are what was
tuned and measured, it costs one contact pair per step, and it behaves the same for any
placement. A hydroelastic pen would need a compliant-hydroelastic mesh of the tip and a
modulus for the paper, neither known for a felt tip, and a thin sheet is the case where
hydroelastic pressure fields are least accurate. Relying on ``hydroelastic_with_fallback``
gave the same point contact only because neither geometry had hydroelastic properties.

The plan (:func:`~hemg_drake.tasks.plans.default_drawing_plan`, beside the other plans, so
that a scenario builds it without a plant) draws a line, an arc and a zig-zag with pen lifts
between them, the six steps I-VI of Fig. 10 (see :func:`~hemg_drake.tasks.plans.
drawing_steps`); pen-down segments put the tip
``press_depth`` below the paper so that the pen presses. The pen's contact force is
``f_WE`` of a :class:`~hemg_drake.tasks.sensors.ContactForceSensor` on the hand.
"""

import copy
import dataclasses as dc

import numpy as np
from pydrake.geometry import AddContactMaterial, Cylinder, ProximityProperties, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.plant import ContactModel, CoulombFriction

from hemg_drake.robots.baxter import MODELS_DIR, make_parser
from hemg_drake.tasks.config import DrawingParams
from hemg_drake.tasks.placement import DEFAULT_POSITIONS, checked_scene_pose
from hemg_drake.tasks.sensors import ContactForceSensor

DRAWING_MODEL = MODELS_DIR / "drawing.sdf"
# Centre of the sheet's top surface by default (m, W; hemg_drake.tasks.placement says why).
DEFAULT_POSITION = DEFAULT_POSITIONS["drawing"]
# A4, as in the model file: (x, y) extent of the sheet (m).
SHEET_SIZE = (0.210, 0.297)
_PEN_GREEN = (0.1, 0.6, 0.25, 1.0)




@dc.dataclass(frozen=True, eq=False)
class DrawingScene:
    """Handles to the drawing scene in a plant, from :func:`add_drawing_scene`.

    Attributes
    ----------
    plant : MultibodyPlant
    model_instance : ModelInstanceIndex, the table and sheet.
    pen_body : Body, the arm's ``right_hand``, which carries the pen.
    pen_tip_frame : Frame, the arm's tool frame: its origin is the pen's tip P.
    sheet_size : (float, float), the sheet's x and y extent (m), along T's x and y.
    params : DrawingParams
    X_WT : RigidTransform, the scene frame: the sheet's top-surface centre at its origin.
    """

    plant: object
    model_instance: object
    pen_body: object
    pen_tip_frame: object
    sheet_size: tuple
    params: DrawingParams
    X_WT: RigidTransform

    @property
    def paper_center(self):
        """Centre of the sheet's top surface in W (m), shape (3,): the origin of T, raised by
        ``params.sheet_offset``."""
        return self.X_WT.translation() + [0.0, 0.0, self.params.sheet_offset]

    @property
    def paper_height(self):
        """z of the sheet's top surface in W (m)."""
        return float(self.paper_center[2])

    def add_systems(self, builder):
        """Add the pen's :class:`ContactForceSensor` to ``builder`` (once; later calls reuse it).

        Call after ``plant.Finalize()``. Returns the sensor, named ``pen_force``.
        """
        if builder.HasSubsystemNamed("pen_force"):
            return builder.GetSubsystemByName("pen_force")
        sensor = builder.AddNamedSystem(
            "pen_force", ContactForceSensor(plant=self.plant, body=self.pen_body)
        )
        builder.Connect(self.plant.get_contact_results_output_port(), sensor.contact_results_input)
        return sensor

    def force_output_port(self, builder):
        """The paper's force ``f_WE`` on the pen (3, N, in W); adds the sensor if needed."""
        return self.add_systems(builder).f_WE_output


def add_drawing_scene(plant, arm, *, params=None, X_WT=None):
    """Add the table with its A4 sheet, and the pen on the arm's hand, to ``plant``.

    Call before ``plant.Finalize()``. The plant must be discrete (the contact parameters are
    chosen for a 1 ms SAP step) and registered with a ``SceneGraph``.

    Parameters
    ----------
    plant : MultibodyPlant, not finalized.
    arm : BaxterArm; the pen goes on ``hand_frame``'s body, its tip at ``tool_frame``.
    params : DrawingParams, optional (default ``DrawingParams()``).
    X_WT : RigidTransform, optional
        The scene frame (:func:`~hemg_drake.tasks.placement.scene_pose`), a turn about
        world z only; default at ``DEFAULT_POSITION``, unturned.

    Returns
    -------
    DrawingScene

    Raises
    ------
    ValueError
        Bad parameters (naming the field), a finalized or continuous plant, a contact model
        other than point contact, or a plant without a SceneGraph.
    """
    params = (DrawingParams() if params is None else params).check()
    X_WT = checked_scene_pose(X_WT, "drawing", what="sheet")
    if plant.is_finalized():
        raise ValueError("add_drawing_scene must be called before plant.Finalize()")
    if not plant.time_step() > 0:
        raise ValueError("the drawing scene needs a discrete plant (time_step > 0)")
    if plant.get_contact_model() != ContactModel.kPoint:
        raise ValueError(
            "the drawing scene needs point contact (plant config contact_model: point), got "
            f"{plant.get_contact_model()}; see hemg_drake.tasks.drawing for why"
        )
    if not plant.geometry_source_is_registered():
        raise ValueError("the drawing scene needs a plant registered with a SceneGraph")
    (model,) = make_parser(plant).AddModels(str(DRAWING_MODEL))
    # sheet_offset moves the physical sheet along T's z, off where the plan expects it.
    plant.WeldFrames(
        plant.world_frame(),
        plant.GetFrameByName("table", model),
        X_WT @ RigidTransform([0.0, 0.0, params.sheet_offset]),
    )
    _add_pen(plant, arm, params)
    return DrawingScene(
        plant=plant,
        model_instance=model,
        pen_body=arm.hand_frame.body(),
        pen_tip_frame=arm.tool_frame,
        sheet_size=SHEET_SIZE,
        params=copy.deepcopy(params),  # the scene's own: later edits cannot change it
        X_WT=RigidTransform(X_WT),
    )


def _add_pen(plant, arm, params):
    """Tip sphere (collision and visual) ending at the tool point, and a pen body (visual)."""
    hand = arm.hand_frame.body()
    radius = params.pen_radius
    # The tool frame E's z points out of the hand: the sphere's centre sits r behind E.
    X_BE = arm.tool_frame.GetFixedPoseInBodyFrame()
    X_BTip = X_BE @ RigidTransform([0.0, 0.0, -radius])
    properties = ProximityProperties()
    AddContactMaterial(
        dissipation=params.pen_dissipation,
        point_stiffness=params.pen_stiffness,
        friction=CoulombFriction(params.pen_friction, params.pen_friction),
        properties=properties,
    )
    plant.RegisterCollisionGeometry(hand, X_BTip, Sphere(radius), "pen_tip", properties)
    plant.RegisterVisualGeometry(hand, X_BTip, Sphere(radius), "pen_tip", np.array(_PEN_GREEN))
    # The barrel, thicker than the model's stub, from 7 cm behind the tip to just above it.
    length = 0.07
    plant.RegisterVisualGeometry(
        hand,
        X_BE @ RigidTransform([0.0, 0.0, -2.0 * radius - 0.5 * length]),
        Cylinder(0.0095, length),
        "pen_barrel",
        np.array(_PEN_GREEN),
    )
