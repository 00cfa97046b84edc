"""CLIK and the arm's start configuration: step cost, pen tilt while drawing, IK time.

1. One ``Clik`` update (the 1 kHz callback itself, this process's CPU time, best of
   7 x 2000 calls) for each law, without and with the pen-axis task (``orientation_gain``
   10 1/s).
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

import time

import numpy as np
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, ContactModel
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from hemg_drake.control.clik import Clik, velocity_columns
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
    print("Clik update (the callback, us of CPU time per call; best / median of 7 x 2000)")
    for method, gain in (("transpose", 300.0), ("dls", 50.0)):
        for axis_gain in (0.0, AXIS_GAIN):
            clik = Clik(
                plant=plant,
                model_instance=arm.model_instance,
                frame_E=arm.tool_frame,
                method=method,
                gain=gain,
                orientation_gain=axis_gain,
            )
            context = clik.CreateDefaultContext()
            target = clik.p_WE(arm.home_positions) + [0.05, 0.02, -0.03]
            clik.GetInputPort("p_WE_desired").FixValue(context, target)
            clik.GetInputPort("state").FixValue(context, np.r_[arm.home_positions, np.zeros(7)])
            context.SetDiscreteState(0, arm.home_positions)
            out = clik.AllocateDiscreteVariables()
            update = clik._update_axis if axis_gain else clik._update  # the periodic event's
            update(context, out)  # compile
            times = []
            for _ in range(7):
                start = time.process_time()
                for _ in range(2000):
                    update(context, out)
                times.append((time.process_time() - start) / 2000 * 1e6)
            print(
                f"  {method:9s} axis task {'on ' if axis_gain else 'off'}: "
                f"{min(times):5.1f} / {np.median(times):5.1f}"
            )


def draw(position, axis_gain):
    """The whole default plan on the shipped drawing scenario's station (plan follower at
    K = 100) with the sheet at ``position``; returns (max tilt in contact (deg), strokes,
    ink's farthest point from the plan (m), wall s, simulated s)."""
    scenario = load_scenario(shipped_scenario("drawing"), overrides=[
        f"scene.position={list(position)}", f"clik.orientation_gain={axis_gain}",
    ])  # fmt: skip
    follower = build_plan_follower(scenario, gain=100.0)
    plan, plant, arm = follower.plan, follower.plant, follower.station.arm
    builder = DiagramBuilder()
    diagram = builder.AddSystem(follower.diagram)
    state_log = LogVectorOutput(diagram.GetOutputPort("arm_state"), builder, 0.01)
    force_log = LogVectorOutput(diagram.GetOutputPort("f_WE"), builder, 0.01)
    simulator = Simulator(builder.Build())
    start = time.perf_counter()
    simulator.AdvanceTo(plan.end_time)
    wall = time.perf_counter() - start
    context = simulator.get_context()
    states = state_log.FindLog(context)
    fk = plant.CreateDefaultContext()
    tilt, p_WP = [], []
    for q in states.data()[:7].T:
        plant.SetPositions(fk, arm.model_instance, q)
        X_WE = arm.tool_frame.CalcPoseInWorld(fk)
        tilt.append(np.degrees(np.arccos(np.clip(-X_WE.rotation().matrix()[2, 2], -1, 1))))
        p_WP.append(X_WE.translation())
    touching = in_contact(force_log.FindLog(context).data().T)
    strokes = ink_strokes(states.sample_times(), np.array(p_WP), touching)
    # Each ink stroke's farthest point from the plan's pen-down path (m, on the paper).
    t = np.arange(plan.start_time, plan.end_time, 0.005)
    planned = plan.position(t[[plan.segment(ti).pen_down for ti in t]])[:, :2]
    error = max(_distance_to_polyline(ink[:, :2], planned).max() for ink in strokes)
    return np.max(np.array(tilt)[touching]), len(strokes), error, wall, plan.end_time


def _distance_to_polyline(points, polyline):
    """Distance (m) from each point (n, d) to the nearest sample of a dense path (k, d)."""
    return np.linalg.norm(points[:, None] - polyline[None], axis=-1).min(axis=1)


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
