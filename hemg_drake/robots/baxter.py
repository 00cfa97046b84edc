"""The Baxter right arm (7 DOF) in a ``MultibodyPlant``: loading, frames, limits.

The model is ``models/baxter_right_arm.urdf``, written from the published facts in
``docs/facts.md`` (joint origins, axes, limits, inertials of Rethink's
``baxter_description``). It is found as this package's data (see :func:`find_models_dir`),
never from the current directory, and parsed with the package map entry
``package://hemg_drake_models/``.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, ModelInstanceIndex

# Found without pydrake (so the task plans can read the files too); public here as before.
from hemg_drake.model_files import MODELS_DIR, find_models_dir  # noqa: F401

PACKAGE_NAME = "hemg_drake_models"
BAXTER_URDF = MODELS_DIR / "baxter_right_arm.urdf"

# Order of the arm's positions, velocities and actuators everywhere in the project.
JOINT_NAMES = ("right_s0", "right_s1", "right_e0", "right_e1", "right_w0", "right_w1", "right_w2")
# Elbow bent, forearm tilted down, hand in front of the robot: close to the Baxter SDK's
# "neutral" pose, far from every joint limit, gravity loading shoulder, elbow and wrist.
HOME_POSITIONS = np.array([0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0])
# Height of the floor in the world (base frame welded at the origin): the pedestal's foot in
# the URDF, 0.93 m below base.
FLOOR_Z = -0.93


@dataclass(frozen=True)
class BaxterArm:
    """Handles to the arm inside a plant, returned by :func:`add_baxter_arm`.

    Arrays have shape (7,) in the order of ``joint_names`` (right_s0 ... right_w2); SI units.

    Attributes
    ----------
    model_instance : ModelInstanceIndex
    joint_names : tuple of str, the seven revolute joints.
    mount_frame : Frame, ``right_arm_mount`` (the arm's base; the facts' FK reference).
    hand_frame : Frame, ``right_hand`` (flange; z points out of the hand).
    tool_frame : Frame, ``right_tool``: 0.1 m along the hand's z, the CLIK end-effector point.
    position_lower, position_upper : array, shape (7,), rad.
    velocity_limit : array, shape (7,), rad/s (symmetric).
    effort_limit : array, shape (7,), N·m (symmetric; s1 = 100 N·m, see the URDF).
    home_positions : array, shape (7,), rad, a nominal configuration.
    """

    model_instance: ModelInstanceIndex
    joint_names: tuple
    mount_frame: Frame
    hand_frame: Frame
    tool_frame: Frame
    position_lower: np.ndarray
    position_upper: np.ndarray
    velocity_limit: np.ndarray
    effort_limit: np.ndarray
    home_positions: np.ndarray


def make_parser(plant):
    """A ``Parser`` for ``plant`` that resolves ``package://hemg_drake_models/`` to models/."""
    parser = Parser(plant)
    parser.package_map().Add(PACKAGE_NAME, str(MODELS_DIR))
    return parser


def add_baxter_arm(plant, scene_graph=None, *, weld_base=True, model_path=None):
    """Add the Baxter right arm on its torso and pedestal to ``plant``.

    Self-collisions of the robot are filtered in the model, so only contacts between the arm
    and a scene count. The joints' default angles are ``HOME_POSITIONS``, so a new context
    starts there. Call before ``plant.Finalize()``.

    Parameters
    ----------
    plant : MultibodyPlant, not finalized.
    scene_graph : SceneGraph, optional. Registers ``plant`` as its geometry source if that has
        not been done yet (``AddMultibodyPlantSceneGraph`` already does it).
    weld_base : bool
        Weld the ``base`` frame to the world at the identity (the test vectors assume it).
    model_path : path-like, optional
        Another URDF/SDFormat file with the same frame and joint names; default ``BAXTER_URDF``.

    Returns
    -------
    BaxterArm

    Raises
    ------
    FileNotFoundError
        The model file does not exist.
    ValueError
        The model file cannot be parsed or lacks the arm's joints, frames or actuators.
    """
    path = Path(model_path) if model_path is not None else BAXTER_URDF
    if not path.is_file():
        raise FileNotFoundError(f"robot model file not found: {path}")
    if scene_graph is not None and not plant.geometry_source_is_registered():
        plant.RegisterAsSourceForSceneGraph(scene_graph)
    try:
        (model,) = make_parser(plant).AddModels(str(path))
    except (RuntimeError, ValueError) as error:
        # Drake's message can span many lines; its first one names the problem.
        reason = (str(error).strip().splitlines() or [type(error).__name__])[0]
        raise ValueError(f"malformed robot model {path}: {reason}") from None

    def frame(name):
        if not plant.HasFrameNamed(name, model):
            raise ValueError(f"robot model {path} has no frame named {name!r}")
        return plant.GetFrameByName(name, model)

    if weld_base:
        plant.WeldFrames(plant.world_frame(), frame("base"))
    for name in JOINT_NAMES:
        if not plant.HasJointNamed(name, model):
            raise ValueError(f"robot model {path} has no joint named {name!r}")
    joints = [plant.GetJointByName(name, model) for name in JOINT_NAMES]
    for joint, angle in zip(joints, HOME_POSITIONS, strict=True):
        joint.set_default_angle(angle)
    efforts = _effort_limits(plant, model, joints, path)
    return BaxterArm(
        model_instance=model,
        joint_names=JOINT_NAMES,
        mount_frame=frame("right_arm_mount"),
        hand_frame=frame("right_hand"),
        tool_frame=frame("right_tool"),
        position_lower=np.array([j.position_lower_limits()[0] for j in joints]),
        position_upper=np.array([j.position_upper_limits()[0] for j in joints]),
        velocity_limit=np.array([j.velocity_upper_limits()[0] for j in joints]),
        effort_limit=efforts,
        home_positions=HOME_POSITIONS.copy(),
    )


def _effort_limits(plant, model, joints, path):
    """Effort limits in joint order; the actuation port must follow the same order."""
    # GetJointActuatorIndices(model) is empty before Finalize(); filter all actuators instead.
    actuators = [plant.get_joint_actuator(i) for i in plant.GetJointActuatorIndices()]
    actuators = [a for a in actuators if a.model_instance() == model]
    actuated = [a.joint().name() for a in actuators]
    if actuated != [j.name() for j in joints]:
        raise ValueError(
            f"robot model {path}: actuators must drive {list(JOINT_NAMES)} in that order "
            f"(found {actuated}); declare one transmission per joint"
        )
    return np.array([a.effort_limit() for a in actuators])


def make_arm_controller_plant(*, model_path=None):
    """A plant of the arm alone, for controllers: kinematics, M(q) and g(q), nothing else.

    As in Drake's ``manipulation/station.py``: the simulated plant also holds the task's
    scene, while a controller models only the robot it drives. The arm's trees do not touch
    the scene's, so its mass matrix and gravity forces are those of the arm's columns of the
    simulated plant (velocities 0..6 here, in ``JOINT_NAMES`` order). The plant is continuous
    (``time_step=0``), has no ``SceneGraph``, and converts to AutoDiffXd.

    Parameters
    ----------
    model_path : path-like, optional, as for :func:`add_baxter_arm`.

    Returns
    -------
    (MultibodyPlant, BaxterArm), the plant finalized.
    """
    plant = MultibodyPlant(time_step=0.0)
    arm = add_baxter_arm(plant, model_path=model_path)
    plant.Finalize()
    plant.set_name("controller_plant")
    return plant, arm
