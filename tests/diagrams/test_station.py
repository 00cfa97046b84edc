"""The slave station through Drake: its ports, its free input, its scenes and where they stand."""

import copy

import numpy as np
import pytest
from pydrake.geometry import Box
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, PortDataType
from pydrake.systems.primitives import ConstantVectorSource

from hemg_drake.control.ik import solve_tool_point_ik
from hemg_drake.control.pd import STIFFNESS_SCALE
from hemg_drake.diagrams.plan_follower import build_plan_follower
from hemg_drake.diagrams.station import make_slave_station
from hemg_drake.robots.baxter import HOME_POSITIONS
from hemg_drake.scenario import Scenario, load_scenario, shipped_scenario
from hemg_drake.tasks import cotter_pin, drawing, plans

GRAVITY = 9.81
# A scene moved and turned away from its default place (m, deg).
MOVED_PIN = [0.66, -0.78, 0.14]
MOVED_SHEET = [0.62, -0.80, 0.10]
YAW_DEG = 30.0


def rotation_z(degrees):
    """R_z written out: a turn of ``degrees`` about world +z."""
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def drawing_scenario():
    return load_scenario(shipped_scenario("drawing"))


def simulate(make, duration, *, reference=None, gain=50.0, force=None):
    """A new station from ``make()`` alone, its inputs held constant; ``force`` feeds
    applied_generalized_force (left unconnected when None). Returns the station's diagram (a
    subsystem of the simulated one) and the simulator after ``duration``."""
    station = make()
    builder = DiagramBuilder()
    slave = builder.AddSystem(station.diagram)

    def hold(value, port):
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value, dtype=float)))
        builder.Connect(source.get_output_port(), slave.GetInputPort(port))

    if slave.HasInputPort("p_WE_desired"):
        hold(reference, "p_WE_desired")
    else:
        hold(station.q0 if reference is None else reference, "q_desired")
        hold(np.zeros(7), "v_desired")
    hold([gain], "gain")
    if force is not None:
        hold(force, "applied_generalized_force")
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(duration)
    return slave, simulator


def output(slave, simulator, name):
    """The station's output ``name`` in the simulator's context."""
    return slave.GetOutputPort(name).Eval(slave.GetMyContextFromRoot(simulator.get_context()))


def ports(system, count, get):
    found = {}
    for i in range(count):
        port = get(i)
        vector = port.get_data_type() == PortDataType.kVectorValued
        found[port.get_name()] = port.size() if vector else "abstract"
    return found


def test_ports_names_and_sizes(pin_scenario):
    station = make_slave_station(pin_scenario)
    diagram = station.diagram
    # The pin's slide joint adds one velocity to the arm's seven.
    assert station.plant.num_velocities() == 8
    assert ports(diagram, diagram.num_input_ports(), diagram.get_input_port) == {
        "p_WE_desired": 3, "gain": 1, "applied_generalized_force": 8,
    }  # fmt: skip
    assert ports(diagram, diagram.num_output_ports(), diagram.get_output_port) == {
        "p_WE": 3, "v_WE": 3, "R_WE": 9, "f_WE": 3, "arm_state": 14, "tau": 7, "q_desired": 7,
        "contact_results": "abstract", "query_object": "abstract",
    }  # fmt: skip  (f_block only with a scene.block)
    for name in ("plant", "scene_graph", "clik", "pd", "tool_point", "cotter_pin_detent"):
        assert diagram.HasSubsystemNamed(name), name
    assert diagram.get_name() == "station"

    joints = make_slave_station(pin_scenario, reference="joints", scene=False, q0=HOME_POSITIONS)
    diagram = joints.diagram
    assert ports(diagram, diagram.num_input_ports(), diagram.get_input_port) == {
        "q_desired": 7, "v_desired": 7, "gain": 1, "applied_generalized_force": 7,
    }  # fmt: skip
    assert not diagram.HasOutputPort("q_desired") and not diagram.HasSubsystemNamed("clik")
    np.testing.assert_array_equal(joints.q0, HOME_POSITIONS)
    with pytest.raises(ValueError, match="reference must be one of"):
        make_slave_station(pin_scenario, reference="torques")
    with pytest.raises(ValueError, match="out of the arm's reach"):
        make_slave_station(pin_scenario, start=[2.5, 0.0, 0.0], scene=False)


def test_a_start_5_cm_above_the_sheet_is_reached_where_ik_from_home_stalls(drawing_scenario):
    """Issue 23's starts: 5 cm above the drawing's first point is in reach, but SNOPT from
    the arm's home stops infeasible at the joint limits (the bench's drawing start failed);
    the station starts there from the IK at the plan's first point. Checked by Drake's
    forward kinematics of the station's q0."""
    start = np.asarray(drawing_scenario.task_plan().points[0]) + [0.0, 0.0, 0.05]
    station = make_slave_station(drawing_scenario, start=start)
    down = dict(axis_E=[0.0, 0.0, 1.0], axis_W=[0.0, 0.0, -1.0])
    with pytest.raises(ValueError, match="out of the arm's reach"):  # the case stays a case
        solve_tool_point_ik(station.plant, station.arm, start, **down)
    X_WE = station.arm.tool_frame.CalcPoseInWorld(station.plant.CreateDefaultContext())
    assert np.linalg.norm(X_WE.translation() - start) < 1e-3
    pen_W = X_WE.rotation().matrix()[:, 2]
    assert np.degrees(np.arccos(-pen_W[2])) < np.degrees(0.05) + 1e-6


def test_tool_point_outputs_against_finite_differences(pin_scenario):
    """p_WE starts on the plan's first point; v_WE is the derivative of p_WE along v."""
    station = make_slave_station(pin_scenario, scene=False)
    diagram, plant, arm = station.diagram, station.plant, station.arm
    context = diagram.CreateDefaultContext()
    plant_context = station.plant_context(context)
    start = pin_scenario.task_plan().points[0]
    np.testing.assert_allclose(diagram.GetOutputPort("p_WE").Eval(context), start, atol=1e-6)
    q = station.q0
    v = np.array([0.3, -0.2, 0.5, 0.1, -0.4, 0.25, 0.6])
    plant.SetVelocities(plant_context, arm.model_instance, v)
    np.testing.assert_array_equal(diagram.GetOutputPort("arm_state").Eval(context), [*q, *v])
    h = 1e-6

    def p_at(qs):
        plant.SetPositions(plant_context, arm.model_instance, qs)
        return diagram.GetOutputPort("p_WE").Eval(context).copy()

    def R_at(qs):
        plant.SetPositions(plant_context, arm.model_instance, qs)
        return diagram.GetOutputPort("R_WE").Eval(context).reshape(3, 3).copy()

    numeric = (p_at(q + h * v) - p_at(q - h * v)) / (2 * h)
    R_dot = (R_at(q + h * v) - R_at(q - h * v)) / (2 * h)
    plant.SetPositions(plant_context, arm.model_instance, q)
    np.testing.assert_allclose(diagram.GetOutputPort("v_WE").Eval(context), numeric, atol=1e-7)
    assert np.linalg.norm(numeric) > 0.05
    # R_WE, row after row, is the tool frame's rotation (Drake's frame API), a rotation whose
    # derivative along v is [w_WE]x R_WE, w_WE the frame's angular velocity (its Jacobian).
    R_WE = diagram.GetOutputPort("R_WE").Eval(context).reshape(3, 3)
    world = plant.world_frame()
    expected = plant.CalcRelativeRotationMatrix(plant_context, world, arm.tool_frame).matrix()
    np.testing.assert_allclose(R_WE, expected, atol=1e-15)
    np.testing.assert_allclose(R_WE @ R_WE.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(R_WE) == pytest.approx(1.0, abs=1e-14)
    J = plant.CalcJacobianSpatialVelocity(
        plant_context, JacobianWrtVariable.kV, arm.tool_frame, np.zeros(3), world, world
    )
    w_WE = J[:3] @ plant.GetVelocities(plant_context)
    skew = R_dot @ R_WE.T
    np.testing.assert_allclose(skew, -skew.T, atol=1e-8)
    np.testing.assert_allclose([skew[2, 1], skew[0, 2], skew[1, 0]], w_WE, atol=1e-7)
    assert np.linalg.norm(w_WE) > 0.15  # 0.19 rad/s: the check is not vacuous


def test_free_space_holds_still_with_no_force(pin_scenario, drawing_scenario):
    # applied_generalized_force is left unconnected: the station still runs.
    start = pin_scenario.task_plan().points[0]
    diagram, simulator = simulate(lambda: make_slave_station(pin_scenario, scene=False), 0.5, reference=start)
    np.testing.assert_array_equal(output(diagram, simulator, "f_WE"), np.zeros(3))
    np.testing.assert_allclose(output(diagram, simulator, "p_WE"), start, atol=1e-3)
    # The pen hovering 3 cm above the sheet touches nothing either.
    start = drawing_scenario.task_plan().points[0]
    diagram, simulator = simulate(lambda: make_slave_station(drawing_scenario), 0.3, reference=start)
    np.testing.assert_array_equal(output(diagram, simulator, "f_WE"), np.zeros(3))
    assert output(diagram, simulator, "contact_results").num_point_pair_contacts() == 0


def test_a_generalized_force_deflects_one_joint_by_tau_over_its_stiffness(pin_scenario):
    """Static balance of eq. 20 with gravity compensated: K s_j (q_j - q0_j) = tau_j."""
    gain, joint, tau = 50.0, 3, 5.0  # right_e1, 500 N m/rad at K = 50

    def make():
        return make_slave_station(
            pin_scenario, reference="joints", scene=False, q0=HOME_POSITIONS
        )

    station = make()
    force = np.zeros(7)
    name = station.arm.joint_names[joint]
    force[station.plant.GetJointByName(name).velocity_start()] = tau
    # Unconnected: the arm holds its configuration.
    diagram, simulator = simulate(make, 2.0, gain=gain)
    q_free = output(diagram, simulator, "arm_state")[:7]
    np.testing.assert_allclose(q_free, HOME_POSITIONS, atol=1e-5)
    diagram, simulator = simulate(make, 2.0, gain=gain, force=force)
    x = output(diagram, simulator, "arm_state")
    expected = HOME_POSITIONS.copy()
    expected[joint] += tau / (gain * STIFFNESS_SCALE[joint])  # 0.01 rad
    np.testing.assert_allclose(x[:7], expected, atol=2e-4)
    np.testing.assert_allclose(x[7:], 0.0, atol=1e-4)


def test_the_pin_detent_acts_through_the_pin_actuator(pin_scenario):
    station = make_slave_station(pin_scenario)
    diagram, plant, scene = station.diagram, station.plant, station.scene
    detent = diagram.GetSubsystemByName("cotter_pin_detent")
    actuation = plant.get_actuation_input_port(scene.model_instance)
    assert plant.num_actuated_dofs(scene.model_instance) == 1
    assert diagram.AreConnected(detent.generalized_force_output, actuation)
    # The plant's generalized-force input is fed by nothing inside: it is the exported port.
    applied = plant.get_applied_generalized_force_input_port()
    inside = {(system, index) for system, index in diagram.connection_map()}
    assert (plant, applied.get_index()) not in inside
    exported = diagram.GetInputPort("applied_generalized_force")
    assert diagram.GetInputPortLocators(exported.get_index()) == [(plant, applied.get_index())]


@pytest.fixture(scope="module")
def pushed_pin(pin_scenario):
    """The arm holds the ring still (K = 200); a constant force pushes the pin out along its
    slide through applied_generalized_force: (fraction of hold_force) -> (pin x, f_WE)."""
    start = pin_scenario.task_plan().points[0]
    stations, results = [], {}

    def make():
        stations.append(make_slave_station(pin_scenario))
        return stations[-1]

    for fraction in (None, 0.8, 1.5):
        force = None
        if fraction is not None:
            probe = make_slave_station(pin_scenario)
            force = np.zeros(probe.plant.num_velocities())
            force[probe.scene.pin_joint.velocity_start()] = fraction * probe.scene.hold_force
        diagram, simulator = simulate(make, 1.0, reference=start, gain=200.0, force=force)
        station = stations[-1]
        plant_context = station.plant_context(simulator.get_context())
        results[fraction] = (
            station.scene.pin_displacement(plant_context),
            output(diagram, simulator, "f_WE").copy(),
        )
    return stations[-1].scene, results


def test_a_push_below_the_hold_force_leaves_the_pin_in_the_detent(pushed_pin):
    scene, results = pushed_pin
    params = scene.params
    weight = 0.1 * GRAVITY
    x, f_WE = results[None]
    assert abs(x) < 1e-4  # unconnected: only the pin's weight on the detent
    x, f_WE = results[0.8]
    assert 0.0 < x < params.detent_length
    # At rest along the slide: push - weight - detent spring - grasp's pull on the ring = 0;
    # the grasp pulls the ring by -f_WE (f_WE: its force on the tool).
    push = 0.8 * scene.hold_force
    assert x == pytest.approx((push - weight - f_WE[2]) / params.detent_stiffness, rel=0.02)


def test_a_push_above_the_hold_force_pops_the_pin(pushed_pin):
    scene, results = pushed_pin
    x, f_WE = results[1.5]
    assert x > 3 * scene.params.detent_length  # past the detent, which no longer acts
    # Along the slide, all of the push but the pin's weight now goes into the grasp, onto the
    # tool (across it, the rail holds the ring while the pulled arm leans).
    assert f_WE[2] == pytest.approx(1.5 * scene.hold_force - 0.1 * GRAVITY, abs=0.05)


def test_the_drawing_scene_needs_point_contact():
    scenario = Scenario(task="drawing")
    assert scenario.plant.contact_model == "point"
    # A scenario refuses the pair (tests/test_scenario_checks.py); the station on its own too.
    with pytest.raises(ValueError, match=r"'plant\.contact_model' = 'hydroelastic_with_fallback'"):
        scenario.replaced(["plant.contact_model=hydroelastic_with_fallback"])
    hydro = copy.deepcopy(scenario)
    hydro.plant.contact_model = "hydroelastic_with_fallback"
    with pytest.raises(ValueError, match=r"drawing scene needs point contact.*contact_model"):
        make_slave_station(hydro)
    # Free space takes any contact model.
    make_slave_station(hydro, scene=False)


def test_a_moved_turned_pin_fixture_stands_where_the_scenario_says(pin_scenario):
    moved = pin_scenario.replaced([f"scene.position={MOVED_PIN}", f"scene.yaw_deg={YAW_DEG}"])
    station = make_slave_station(moved)
    plant, scene = station.plant, station.scene
    context = station.plant_context(station.diagram.CreateDefaultContext())
    X_WR = scene.ring_frame.CalcPoseInWorld(context)
    np.testing.assert_allclose(X_WR.translation(), MOVED_PIN, atol=1e-12)
    fixture = plant.GetFrameByName("fixture", scene.model_instance).CalcPoseInWorld(context)
    np.testing.assert_allclose(fixture.rotation().matrix(), rotation_z(YAW_DEG), atol=1e-12)
    np.testing.assert_allclose(X_WR.rotation().matrix(), rotation_z(YAW_DEG), atol=1e-12)
    # The arm starts with its tool on the ring; the plan rises straight up from it.
    p_WE = station.arm.tool_frame.CalcPoseInWorld(context).translation()
    np.testing.assert_allclose(p_WE, MOVED_PIN, atol=1e-6)
    plan = moved.task_plan()
    rises = [0.0, 0.0, 0.065, 0.10, 0.10]
    np.testing.assert_allclose(plan.points, np.add(MOVED_PIN, np.outer(rises, [0, 0, 1])))


def test_a_moved_turned_sheet_and_its_strokes_stand_where_the_scenario_says(drawing_scenario):
    moved = drawing_scenario.replaced(
        [f"scene.position={MOVED_SHEET}", f"scene.yaw_deg={YAW_DEG}"]
    )
    station = make_slave_station(moved)
    plant, scene = station.plant, station.scene
    context = station.plant_context(station.diagram.CreateDefaultContext())
    inspector = station.diagram.GetSubsystemByName("scene_graph").model_inspector()
    table = plant.GetBodyByName("table", scene.model_instance)
    (sheet,) = plant.GetCollisionGeometriesForBody(table)
    box = inspector.GetShape(sheet)
    assert isinstance(box, Box) and (box.width(), box.depth()) == pytest.approx((0.210, 0.297))
    X_WS = plant.EvalBodyPoseInWorld(context, table) @ inspector.GetPoseInFrame(sheet)
    top = X_WS @ np.array([0.0, 0.0, box.height() / 2])
    np.testing.assert_allclose(top, MOVED_SHEET, atol=1e-12)
    # The sheet's long side (y) turned by the yaw.
    np.testing.assert_allclose(X_WS.rotation().matrix(), rotation_z(YAW_DEG), atol=1e-12)
    # The plan is the default one turned about the sheet's centre and carried to it.
    default = plans.default_drawing_plan()
    plan = moved.task_plan()
    expected = (default.points - drawing.DEFAULT_POSITION) @ rotation_z(YAW_DEG).T + MOVED_SHEET
    np.testing.assert_allclose(plan.points, expected, atol=1e-12)
    np.testing.assert_array_equal(plan.times, default.times)
    assert plan.pen_down == default.pen_down
    # The pen starts hovering over the sheet's centre.
    p_WE = station.arm.tool_frame.CalcPoseInWorld(context).translation()
    hover = moved.scene.drawing.hover_height
    np.testing.assert_allclose(p_WE, np.add(MOVED_SHEET, [0, 0, hover]), atol=1e-6)


def test_a_plan_follower_pulls_a_moved_pin_out(pin_scenario):
    moved = pin_scenario.replaced([f"scene.position={MOVED_PIN}", f"scene.yaw_deg={YAW_DEG}"])
    follower = build_plan_follower(moved, gain=100.0)
    assert follower.diagram.GetSubsystemByName("station") is follower.station.diagram
    simulator = Simulator(follower.diagram)
    simulator.AdvanceTo(follower.plan.end_time)
    root = simulator.get_context()
    plant_context = follower.station.plant_context(root)
    assert follower.scene.pin_out(plant_context)
    assert follower.scene.pin_displacement(plant_context) > 0.09
    # Lifted clear with the pin: the tool is near the plan's last point.
    p_WE = follower.diagram.GetOutputPort("p_WE").Eval(root)
    np.testing.assert_allclose(p_WE, follower.plan.points[-1], atol=0.01)
    assert cotter_pin.PULL_AXIS_W @ (p_WE - np.array(MOVED_PIN)) > 0.09


def _run_logged(station, diagram, duration, reference, gain):
    """Simulate a station's diagram (or its clone) with constant inputs; its logged outputs."""
    from pydrake.systems.primitives import LogVectorOutput

    builder = DiagramBuilder()
    slave = builder.AddSystem(diagram)
    for name, value in (("p_WE_desired", reference), ("gain", [gain])):
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value, dtype=float)))
        builder.Connect(source.get_output_port(), slave.GetInputPort(name))
    logs = [
        LogVectorOutput(slave.GetOutputPort(name), builder, 1e-3)
        for name in ("arm_state", "f_WE", "p_WE", "v_WE")
    ]
    simulator = Simulator(builder.Build())
    station.set_start(simulator.get_mutable_context(), diagram)
    simulator.AdvanceTo(duration)
    return [log.FindLog(simulator.get_context()).data() for log in logs]


def test_the_station_clones_and_a_clone_runs_bit_identical(pin_scenario):
    """Clone() (Drake's double -> double scalar conversion of every system) succeeds, and the
    clone and the original give the same bytes: the pin pulled 3 cm up for 0.2 s."""
    station = make_slave_station(pin_scenario)
    clone = station.diagram.Clone()
    assert clone.HasSubsystemNamed("clik") and clone.HasSubsystemNamed("cotter_pin_force")
    reference = pin_scenario.task_plan().points[0] + np.array([0.0, 0.0, 0.03])
    original = _run_logged(station, station.diagram, 0.2, reference, 200.0)
    cloned = _run_logged(station, clone, 0.2, reference, 200.0)
    for a, b in zip(original, cloned, strict=True):
        np.testing.assert_array_equal(a, b)
    assert np.abs(original[1]).max() > 1.0  # the grasp pulled: a force to compare


def test_the_free_space_station_converts_to_autodiff(pin_scenario):
    """ToAutoDiffXd() of the station without its scene: the slope of the tool point after
    5 ms with respect to the desired tool point (through CLIK, PD, gravity and the plant)
    against central finite differences of the double station."""
    from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff
    from pydrake.systems.analysis import Simulator_

    station = make_slave_station(pin_scenario, scene=False)
    ad = station.diagram.ToAutoDiffXd()
    start = pin_scenario.task_plan().points[0]
    reference = start + np.array([0.01, -0.01, 0.02])
    duration, gain = 5e-3, 100.0

    simulator = Simulator_[AutoDiffXd](ad)
    context = simulator.get_mutable_context()
    station.set_start(context, ad)
    ad.GetInputPort("p_WE_desired").FixValue(context, InitializeAutoDiff(reference)[:, 0])
    ad.GetInputPort("gain").FixValue(context, [AutoDiffXd(gain)])
    simulator.AdvanceTo(duration)
    p_WE = ad.GetOutputPort("p_WE").Eval(context)
    slope = ExtractGradient(p_WE)

    def p_after(p_desired):
        diagram = station.diagram
        simulator = Simulator(diagram)
        context = simulator.get_mutable_context()
        diagram.GetInputPort("p_WE_desired").FixValue(context, p_desired)
        diagram.GetInputPort("gain").FixValue(context, [gain])
        simulator.AdvanceTo(duration)
        return diagram.GetOutputPort("p_WE").Eval(context).copy()

    h = 1e-5
    numeric = np.column_stack(
        [(p_after(reference + h * u) - p_after(reference - h * u)) / (2 * h) for u in np.eye(3)]
    )
    np.testing.assert_allclose(ExtractValue(p_WE).ravel(), p_after(reference), rtol=0, atol=1e-12)
    assert np.abs(slope).max() > 1e-3  # the tool has started to follow
    np.testing.assert_allclose(slope, numeric, rtol=1e-5, atol=1e-9)
