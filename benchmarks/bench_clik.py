"""CLIK and the arm's start configuration: step cost, pen tilt while drawing, IK time.

1. One ``Clik`` update (the 1 kHz callback itself with its cache entry's position update,
   this process's CPU time, best of 7 x 2000 calls) for each law, without and with the
   pen-axis task (``orientation_gain`` 10 1/s); then, for the DLS variant, one step of
   Drake's ``DifferentialInverseKinematicsIntegrator`` (a QP per step; see
   the module docstring of ``hemg_drake.control.clik``).
2. The pen's tilt from vertical while it touches the paper over the whole default drawing
   plan (the shipped drawing scenario's station followed at K = 100 by
   ``build_plan_follower``, the measured arm's pose logged at 0.01 s), with the
   position-only law and with the axis task, for the earlier sheet and the shipped one;
   the station starts the arm on the plan's first point by IK, with the pen vertical when
   the axis task is on.
3. ``solve_tool_point_ik`` (Drake's InverseKinematics + SNOPT) against the damped Newton
   loop the station used before (written out below), best of 5, on the drawing plant.

Prints its figures; the machine is shared (2 cores), so take the best of several runs.
"""

import dataclasses as dc
import time

import numpy as np
from pydrake.multibody.inverse_kinematics import (
    DifferentialInverseKinematicsIntegrator,
    DifferentialInverseKinematicsParameters,
)
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, ContactModel
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from hemg_drake.control.clik import Clik, velocity_columns
from hemg_drake.control.config import ClikConfig
from hemg_drake.control.ik import solve_tool_point_ik
from hemg_drake.diagrams.plan_follower import build_plan_follower
from hemg_drake.robots.baxter import add_baxter_arm
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.tasks.drawing import DEFAULT_POSITION, add_drawing_scene
from hemg_drake.viz.ink import in_contact, ink_strokes

AXIS_GAIN = 10.0
MOVED_SHEET = (0.60, -0.70, 0.09)


def drawing_plant(builder=None, X_WT=None):
    builder = DiagramBuilder() if builder is None else builder
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    plant.set_contact_model(ContactModel.kPoint)
    arm = add_baxter_arm(plant)
    scene = add_drawing_scene(plant, arm, X_WT=X_WT)
    plant.Finalize()
    return builder, plant, arm, scene


def update_cost():
    _, plant, arm, _ = drawing_plant()
    fk = plant.CreateDefaultContext()
    plant.SetPositions(fk, arm.model_instance, arm.home_positions)
    target = arm.tool_frame.CalcPoseInWorld(fk).translation() + [0.05, 0.02, -0.03]
    print("Clik update (the callback, us of CPU time per call; best / median of 7 x 2000)")
    for method, gain in (("transpose", 300.0), ("dls", 50.0)):
        for axis_gain in (0.0, AXIS_GAIN):
            config = dc.replace(
                ClikConfig(), method=method, gain=gain, orientation_gain=axis_gain
            )
            clik = Clik(
                plant=plant,
                model_instance=arm.model_instance,
                frame_E=arm.tool_frame,
                config=config,
            )
            context = clik.CreateDefaultContext()
            clik.GetInputPort("p_WE_desired").FixValue(context, target)
            clik.GetInputPort("state").FixValue(context, np.r_[arm.home_positions, np.zeros(7)])
            out = clik.AllocateDiscreteVariables()
            update = clik._update_axis if axis_gain else clik._update  # the periodic event's
            times = []
            for _ in range(7):
                start = time.process_time()
                for _ in range(2000):
                    # A new q_d each call, as in a simulation: the cache entry recomputes.
                    context.SetDiscreteState(0, arm.home_positions)
                    update(context, out)
                times.append((time.process_time() - start) / 2000 * 1e6)
            print(
                f"  {method:9s} axis task {'on ' if axis_gain else 'off'}: "
                f"{min(times):5.1f} / {np.median(times):5.1f}"
            )
    # Drake's differential IK integrator, translation only, the same limits (its QP step).
    params = DifferentialInverseKinematicsParameters(plant.num_positions(), plant.num_velocities())
    params.set_end_effector_velocity_flag([False, False, False, True, True, True])
    integrator = DifferentialInverseKinematicsIntegrator(plant, arm.tool_frame, 1e-3, params)
    simulator = Simulator(integrator)
    context = simulator.get_mutable_context()
    X_WE = arm.tool_frame.CalcPoseInWorld(fk)
    X_WE.set_translation(target)
    integrator.GetInputPort("X_WE_desired").FixValue(context, X_WE)
    integrator.GetInputPort("use_robot_state").FixValue(context, False)
    integrator.SetPositions(context, plant.GetPositions(fk))
    times = []
    for _ in range(7):
        start = time.process_time()
        simulator.AdvanceTo(context.get_time() + 0.2)
        times.append((time.process_time() - start) / 200 * 1e6)
    print(
        f"  DifferentialInverseKinematicsIntegrator (a simulated step, QP): "
        f"{min(times):5.1f} / {np.median(times):5.1f}"
    )


def tilt_while_drawing():
    print(f"pen tilt from vertical while touching, whole plan (axis gain {AXIS_GAIN} 1/s)")
    for name, position in (("default sheet", DEFAULT_POSITION), ("moved sheet", MOVED_SHEET)):
        for axis_gain in (0.0, AXIS_GAIN):
            tilt, strokes, error, wall, duration = draw(position, axis_gain)
            print(
                f"  {name} {tuple(position)}, axis task {'on ' if axis_gain else 'off'}: "
                f"max {tilt:5.2f} deg, {strokes} strokes, ink within {1e3 * error:.1f} mm "
                f"of the plan, {duration / wall:.1f}x real time"
            )


def newton_positions(plant, arm, p_WE, iterations=200, damping=0.01):
    """The damped Newton loop that diagrams/slave.py used for the start (the yardstick)."""
    context = plant.CreateDefaultContext()
    world = plant.world_frame()
    columns = velocity_columns(plant, arm.model_instance)
    q = arm.home_positions.copy()
    for _ in range(iterations):
        plant.SetPositions(context, arm.model_instance, q)
        error = p_WE - arm.tool_frame.CalcPoseInWorld(context).translation()
        if np.linalg.norm(error) < 1e-6:
            break
        J = plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kV, arm.tool_frame, np.zeros(3), world, world
        )[:, columns]
        q = np.clip(
            q + J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(3), error),
            arm.position_lower,
            arm.position_upper,
        )
    return q


def ik_time():
    _, plant, arm, _ = drawing_plant()
    print("start configuration (ms, best of 5): Newton loop / InverseKinematics / IK + pen axis")
    fk = plant.CreateDefaultContext()
    for p_WE in ([0.64, -0.84, 0.12], [0.60, -0.70, 0.12], [0.75, -0.50, 0.30]):
        p_WE = np.array(p_WE)
        row = []
        for solve in (
            lambda: newton_positions(plant, arm, p_WE),
            lambda: solve_tool_point_ik(plant, arm, p_WE),
            lambda: solve_tool_point_ik(
                plant, arm, p_WE, axis_E=[0, 0, 1], axis_W=[0, 0, -1], angle_tolerance=0.02
            ),
        ):
            times = []
            for _ in range(5):
                start = time.perf_counter()
                q = solve()
                times.append(time.perf_counter() - start)
            plant.SetPositions(fk, arm.model_instance, q)
            error = np.linalg.norm(arm.tool_frame.CalcPoseInWorld(fk).translation() - p_WE)
            row.append(f"{1e3 * min(times):6.2f} ({error:.0e} m)")
        print(f"  {p_WE.tolist()}: " + " / ".join(row))


if __name__ == "__main__":
    update_cost()
    ik_time()
    tilt_while_drawing()
