"""The Baxter right-arm model against the published facts, through a MultibodyPlant."""

import numpy as np
import pytest
from pydrake.geometry import Sphere
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.common.eigen_geometry import Quaternion
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, CoulombFriction, MultibodyPlant
from pydrake.systems.framework import DiagramBuilder

from hemg_drake.robots.baxter import (
    BAXTER_URDF,
    JOINT_NAMES,
    MODELS_DIR,
    add_baxter_arm,
    find_models_dir,
)


def _facts_rows(facts_dir, name):
    """The 10 configurations of a facts CSV: q (7 columns) then the reference values."""
    rows = np.loadtxt(facts_dir / name, delimiter=",", skiprows=1)
    assert rows.shape == (10, 14), f"{name}: unexpected shape {rows.shape}"
    return rows


@pytest.fixture(scope="module")
def arm_plant():
    # Continuous plant as in the facts' reference computation (time step does not enter FK/g).
    plant = MultibodyPlant(0.0)
    arm = add_baxter_arm(plant)
    plant.Finalize()
    return plant, arm


def test_forward_kinematics_matches_facts(arm_plant, facts_dir):
    # Frames: pose of right_hand expressed in right_arm_mount, as in baxter_fk_vectors.csv.
    plant, arm = arm_plant
    context = plant.CreateDefaultContext()
    for row in _facts_rows(facts_dir, "baxter_fk_vectors.csv"):
        plant.SetPositions(context, arm.model_instance, row[:7])
        X_MH = plant.CalcRelativeTransform(context, arm.mount_frame, arm.hand_frame)
        quaternion = row[10:14] / np.linalg.norm(row[10:14])
        R_MH_ref = RotationMatrix(Quaternion(quaternion))
        position_error = np.linalg.norm(X_MH.translation() - row[7:10])
        angle_error = R_MH_ref.inverse().multiply(X_MH.rotation()).ToAngleAxis().angle()
        assert position_error <= 1e-3, f"q={row[:7]}: position off by {position_error} m"
        assert angle_error <= 1e-3, f"q={row[:7]}: rotation off by {angle_error} rad"


def test_gravity_forces_match_facts(arm_plant, facts_dir):
    plant, arm = arm_plant
    context = plant.CreateDefaultContext()
    for row in _facts_rows(facts_dir, "baxter_gravity_vectors.csv"):
        plant.SetPositions(context, arm.model_instance, row[:7])
        g = plant.GetVelocitiesFromArray(
            arm.model_instance, plant.CalcGravityGeneralizedForces(context)
        )
        g_ref = row[7:]
        # 2 % relative plus 0.01 N·m absolute: several reference entries are near zero.
        assert np.all(np.abs(g - g_ref) <= 0.02 * np.abs(g_ref) + 0.01), (row[:7], g, g_ref)


def test_limits_equal_facts(arm_plant):
    plant, arm = arm_plant
    # From the facts' joint-limit table (s1 effort: the flat URDF's 100 N·m).
    lower = [-1.70167993878, -2.147, -3.05417993878, -0.05, -3.059, -1.57079632679, -3.059]
    upper = [1.70167993878, 1.047, 3.05417993878, 2.618, 3.059, 2.094, 3.059]
    velocity = [1.5, 1.5, 1.5, 1.5, 4.0, 4.0, 4.0]
    effort = [50, 100, 50, 50, 15, 15, 15]
    np.testing.assert_allclose(arm.position_lower, lower, atol=1e-12)
    np.testing.assert_allclose(arm.position_upper, upper, atol=1e-12)
    np.testing.assert_allclose(arm.velocity_limit, velocity, atol=1e-12)
    np.testing.assert_allclose(arm.effort_limit, effort, atol=1e-12)
    # The same numbers as the plant sees them, in the plant's own vectors.
    np.testing.assert_allclose(
        plant.GetPositionsFromArray(arm.model_instance, plant.GetPositionLowerLimits()), lower
    )
    np.testing.assert_allclose(
        plant.GetVelocitiesFromArray(arm.model_instance, plant.GetVelocityUpperLimits()), velocity
    )
    np.testing.assert_allclose(plant.GetEffortUpperLimits(), effort)
    for name in JOINT_NAMES:
        assert plant.GetJointByName(name).default_damping() == pytest.approx(0.7)
    assert np.all(arm.position_lower < arm.home_positions)
    assert np.all(arm.home_positions < arm.position_upper)
    np.testing.assert_allclose(plant.GetDefaultPositions(), arm.home_positions)


def test_mount_and_total_mass(arm_plant):
    plant, arm = arm_plant
    context = plant.CreateDefaultContext()
    X_WM = plant.CalcRelativeTransform(context, plant.world_frame(), arm.mount_frame)
    np.testing.assert_allclose(X_WM.translation(), [0.024645, -0.219645, 0.118588], atol=1e-9)
    bodies = plant.GetBodyIndices(arm.model_instance)
    moving = [plant.get_body(i) for i in bodies if plant.get_body(i).name().startswith("right_")]
    mass = sum(b.default_mass() for b in moving if b.name() != "right_arm_mount")
    assert mass == pytest.approx(19.71082, abs=1e-6)
    # The tool point sits 0.1 m along the hand's z axis.
    X_HT = plant.CalcRelativeTransform(context, arm.hand_frame, arm.tool_frame)
    np.testing.assert_allclose(X_HT.translation(), [0, 0, 0.1], atol=1e-12)


def test_only_arm_versus_scene_contacts_are_candidates():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    add_baxter_arm(plant)
    obstacle = plant.RegisterCollisionGeometry(
        plant.world_body(), RigidTransform([0.6, -0.6, 0.0]), Sphere(0.1), "obstacle",
        CoulombFriction(0.5, 0.5),
    )
    plant.Finalize()
    candidates = scene_graph.model_inspector().GetCollisionCandidates()
    assert len(candidates) > 0
    for a, b in candidates:
        assert obstacle in (a, b), "a robot-robot pair is still a collision candidate"


def test_missing_model_names_the_file(tmp_path):
    missing = tmp_path / "nope.urdf"
    with pytest.raises(FileNotFoundError, match="nope.urdf"):
        add_baxter_arm(MultibodyPlant(0.0), model_path=missing)


def test_malformed_model_names_the_file(tmp_path):
    broken = tmp_path / "broken.urdf"
    broken.write_text(BAXTER_URDF.read_text()[:2000])  # cut mid-element
    with pytest.raises(ValueError, match="broken.urdf"):
        add_baxter_arm(MultibodyPlant(0.0), model_path=broken)


def test_model_without_arm_joints_names_the_file(tmp_path):
    stub = tmp_path / "stub.urdf"
    stub.write_text(
        '<robot name="stub"><link name="base"/><link name="right_arm_mount"/>'
        '<joint name="j" type="fixed"><parent link="base"/><child link="right_arm_mount"/>'
        "</joint></robot>"
    )
    with pytest.raises(ValueError, match="stub.urdf.*right_s0"):
        add_baxter_arm(MultibodyPlant(0.0), model_path=stub)


def test_models_are_found_beside_the_package_or_in_the_installed_copy(tmp_path):
    assert (MODELS_DIR / "package.xml").is_file() and (MODELS_DIR / "cotter_pin.sdf").is_file()
    checkout, installed = tmp_path / "checkout" / "models", tmp_path / "share" / "models"
    installed.mkdir(parents=True)
    (installed / "package.xml").write_text("<package/>")
    # A regular install: nothing beside the package, the data-files copy is used.
    assert find_models_dir([checkout, installed]) == installed
    checkout.mkdir(parents=True)
    (checkout / "package.xml").write_text("<package/>")
    assert find_models_dir([checkout, installed]) == checkout
    # Neither: the first place, where loading a model then names the missing file.
    assert find_models_dir([tmp_path / "a", tmp_path / "b"]) == tmp_path / "a"
