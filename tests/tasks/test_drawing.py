"""Drawing through Drake: the pen follows the plan at a high gain and inks three strokes.

The runs use the plant configuration every scenario runs (the shipped scenario's: point
contact, live output ports), through the plan follower on the slave station.
"""

import dataclasses as dc

import numpy as np
import pytest
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.geometry import Box, Role, Sphere
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    AddMultibodyPlantSceneGraph,
    ContactModel,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from hemg_drake.diagrams.plan_follower import build_plan_follower
from hemg_drake.robots.baxter import add_baxter_arm
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.tasks.drawing import (
    DEFAULT_POSITION,
    SHEET_SIZE,
    DrawingParams,
    add_drawing_scene,
)
from hemg_drake.tasks.plan import TaskPlan
from hemg_drake.tasks.plans import default_drawing_plan, drawing_steps
from hemg_drake.viz.ink import in_contact, ink_strokes

GAIN = 100.0
LOG_PERIOD = 0.01


@pytest.fixture(scope="module")
def product():
    """The shipped drawing scenario on the product's plant configuration (the shipped
    cotter-pin scenario's, which every scenario shares)."""
    plant = load_scenario(shipped_scenario("cotter_pin")).plant
    assert plant.use_sampled_output_ports is False and plant.contact_model == "point"
    scenario = load_scenario(shipped_scenario("drawing"))
    assert yaml_dump_typed(scenario.plant) == yaml_dump_typed(plant)
    return dc.replace(scenario, plant=plant)


def _scene(plant_config, params=None, X_WT=None):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(plant_config, builder)
    arm = add_baxter_arm(plant)
    scene = add_drawing_scene(plant, arm, params=params, X_WT=X_WT)
    plant.Finalize()
    plant.SetDefaultPositions(arm.model_instance, arm.home_positions)
    return builder, plant, scene_graph, arm, scene


def follow(scenario, gain):
    """The default plan at a constant gain: logged tip pose, contact force, planned pen state."""
    follower = build_plan_follower(scenario, gain=gain)
    builder = DiagramBuilder()
    diagram = builder.AddSystem(follower.diagram)
    state_log = LogVectorOutput(diagram.GetOutputPort("arm_state"), builder, LOG_PERIOD)
    tip_log = LogVectorOutput(diagram.GetOutputPort("p_WE"), builder, LOG_PERIOD)
    force_log = LogVectorOutput(diagram.GetOutputPort("f_WE"), builder, LOG_PERIOD)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(follower.plan.end_time)
    context = simulator.get_context()
    states = state_log.FindLog(context)
    plant, arm, plan = follower.plant, follower.station.arm, follower.plan
    # The pen's axis (the tool frame's z) by forward kinematics of the logged joints.
    fk_context = plant.CreateDefaultContext()
    axes = []
    for q in states.data()[:7].T:
        plant.SetPositions(fk_context, arm.model_instance, q)
        axes.append(arm.tool_frame.CalcPoseInWorld(fk_context).rotation().matrix()[:, 2])
    t = states.sample_times()
    return dict(
        scene=follower.scene,
        plan=plan,
        t=t,
        p_WP=tip_log.FindLog(context).data().T,
        Pz_W=np.array(axes),
        f_WP=force_log.FindLog(context).data().T,
        pen_down=np.array([plan.segment(ti).pen_down for ti in t]),
    )


@pytest.fixture(scope="module")
def run(product):
    return follow(product, GAIN)


def _distance_to_polyline(points, polyline):
    """Distance (m) from each point, shape (n, d), to a polyline, shape (k, d)."""
    a, b = polyline[:-1][None], polyline[1:][None]
    p = points[:, None]
    ab = b - a
    w = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-18), 0.0, 1.0)
    return np.linalg.norm(p - (a + w[..., None] * ab), axis=-1).min(axis=1)


def _planned_strokes(plan):
    """The planned pen-down paths, sampled at 5 ms, one (n, 2) array per stroke."""
    t = np.arange(plan.start_time, plan.end_time, 0.005)
    down = np.array([plan.segment(ti).pen_down for ti in t])
    edges = np.flatnonzero(np.diff(np.concatenate([[0], down.astype(int), [0]])))
    return [plan.position(t[a:b])[:, :2] for a, b in zip(edges[0::2], edges[1::2])]


def test_ink_traces_the_three_planned_strokes(run):
    strokes = ink_strokes(run["t"], run["p_WP"], in_contact(run["f_WP"]))
    assert len(strokes) == 3
    for ink, planned in zip(strokes, _planned_strokes(run["plan"])):
        # Shapes on the paper (x, y): plan to ink and ink to plan, within 3.5 mm (docs:
        # 1.5, 2.6, 3.2 mm at K = 100).
        assert _distance_to_polyline(planned, ink[:, :2]).max() < 0.0035
        assert _distance_to_polyline(ink[:, :2], planned).max() < 0.0035
        # The ink lies on the paper: the compliant tip sinks f / k, about 1 mm at 10 N.
        np.testing.assert_allclose(ink[:, 2], run["scene"].paper_height, atol=0.0015)


def test_contact_only_while_the_pen_is_down(run):
    touching = in_contact(run["f_WP"])
    force = np.linalg.norm(run["f_WP"], axis=1)
    # No ink and no force at all during the lifts and moves.
    assert not np.any(touching & ~run["pen_down"])
    assert np.all(force[~run["pen_down"]] == 0.0)
    # While drawing (chords, not press and release), the pen always touches.
    plan = run["plan"]
    chords = np.array([
        plan.pen_down[i] and np.allclose(plan.points[i, 2], plan.points[i + 1, 2])
        for i in range(len(plan.kinds))
    ])  # fmt: skip
    drawing = np.array([chords[plan.segment(ti).index] for ti in run["t"]])
    assert np.all(touching[drawing])


def test_contact_force_is_the_pen_spring(run):
    """While drawing, the normal force is k * depth of the tip sphere (series stiffness)."""
    scene = run["scene"]
    params = scene.params
    k = params.pen_stiffness * 1e6 / (params.pen_stiffness + 1e6)  # the sheet's 1e6 N/m
    r = params.pen_radius
    lowest_z = (run["p_WP"] - r * run["Pz_W"])[:, 2] - r
    depth = scene.paper_height - lowest_z
    touching = in_contact(run["f_WP"])
    steady = touching & (np.abs(np.gradient(depth, run["t"])) < 0.002)
    assert steady.sum() > 200
    np.testing.assert_allclose(run["f_WP"][steady, 2], k * depth[steady], rtol=0.1, atol=0.05)
    # The pen is pressed with a few newtons, up, opposite to the paper's normal push on it.
    assert 1.0 < np.median(run["f_WP"][steady, 2]) < 15.0
    # docs/tasks.md: 7.7 N median over every touching sample at K = 100.
    assert np.median(run["f_WP"][touching, 2]) == pytest.approx(7.7, abs=0.7)


def test_the_pen_stays_upright_while_it_touches(run):
    """The shipped scenario's CLIK holds the pen's axis down: within 5 degrees (measured
    0.6) of the world's -z whenever the pen touches the paper."""
    touching = in_contact(run["f_WP"])
    tilt = np.degrees(np.arccos(np.clip(-run["Pz_W"][:, 2], -1.0, 1.0)))
    assert tilt[touching].max() < 5.0


@pytest.mark.slow
def test_a_compliant_slave_skips(product):
    """K = 20 cannot keep the pen on the paper: the strokes break up (docs/tasks.md)."""
    low = follow(product, 20.0)
    touching = in_contact(low["f_WP"])
    assert len(ink_strokes(low["t"], low["p_WP"], touching)) > 3
    assert not np.any(touching & ~low["pen_down"])


def test_sheet_is_a4_at_the_scene_frame_and_the_pen_tip_is_the_tool_point(product):
    _, plant, scene_graph, arm, scene = _scene(product.plant)
    # The scene's paper centre is a copy: editing it moves nothing.
    scene.paper_center[2] += 0.5
    np.testing.assert_allclose(scene.paper_center, DEFAULT_POSITION, atol=1e-12)
    inspector = scene_graph.model_inspector()
    table = plant.GetBodyByName("table", scene.model_instance)
    (sheet,) = plant.GetCollisionGeometriesForBody(table)
    box = inspector.GetShape(sheet)
    assert isinstance(box, Box)
    assert (box.width(), box.depth()) == pytest.approx(SHEET_SIZE)
    context = plant.CreateDefaultContext()
    X_WT = plant.EvalBodyPoseInWorld(context, table)
    top = X_WT @ inspector.GetPoseInFrame(sheet) @ np.array([0, 0, box.height() / 2])
    np.testing.assert_allclose(top, DEFAULT_POSITION, atol=1e-12)
    assert scene.paper_height == pytest.approx(DEFAULT_POSITION[2])
    (tip,) = [
        g for g in plant.GetCollisionGeometriesForBody(scene.pen_body)
        if isinstance(inspector.GetShape(g), Sphere)
    ]  # fmt: skip
    radius = inspector.GetShape(tip).radius()
    X_WH = plant.EvalBodyPoseInWorld(context, scene.pen_body)
    X_WTip = X_WH @ inspector.GetPoseInFrame(tip)
    # The sphere's point furthest along the tool's z is the tool point E.
    p_WE = arm.tool_frame.CalcPoseInWorld(context)
    far = X_WTip.translation() + radius * p_WE.rotation().matrix()[:, 2]
    np.testing.assert_allclose(far, p_WE.translation(), atol=1e-12)
    assert inspector.GetProperties(tip, Role.kProximity) is not None
    # The plan starts where the pen is at the arm's home pose (so a run can start there).
    assert np.linalg.norm(default_drawing_plan().points[0] - p_WE.translation()) < 0.005


def test_plan_has_three_strokes_and_six_steps_on_the_sheet():
    params = DrawingParams()
    plan = default_drawing_plan(params)
    steps = drawing_steps(plan)
    assert steps.shape == (7,) and np.all(np.diff(steps) > 0)
    center = np.array(DEFAULT_POSITION)
    above_center = center + [0, 0, params.hover_height]
    np.testing.assert_allclose(plan.points[[0, -1]], [above_center, above_center])
    down = np.array(plan.pen_down)
    assert all(k == ("forceful" if d else "free") for k, d in zip(plan.kinds, down))
    # Pen-down waypoints lie over the sheet; the drawing ones press press_depth into it.
    for i in np.flatnonzero(down):
        for p in plan.points[i : i + 2]:
            assert np.all(np.abs(p[:2] - center[:2]) < np.array(SHEET_SIZE) / 2)
    lengths = []
    for start, end in zip(steps[[0, 2, 4]], steps[[1, 3, 5]]):
        t = np.linspace(start, end, 2000)
        path = plan.position(t)
        pressing = path[:, 2] < center[2] - 0.999 * params.press_depth
        lengths.append(np.linalg.norm(np.diff(path[pressing, :2], axis=0), axis=1).sum())
    # A line, a half circle and a zig-zag, a few centimetres to about 15 cm each.
    expected = [0.11, np.pi * 0.045, 4 * np.hypot(0.04, 0.015)]
    np.testing.assert_allclose(lengths, expected, rtol=0.02)
    # Between the strokes the pen is up above the paper, at the hover height.
    for start, end in zip(steps[[1, 3, 5]], steps[[2, 4, 6]]):
        t = np.linspace(start, end, 200)
        assert np.all(plan.position(t)[:, 2] > center[2])


def test_drawing_steps_needs_three_strokes():
    plan = TaskPlan(
        times=[0, 1, 2, 3],
        points=np.zeros((4, 3)),
        kinds=["free"] * 3,
        pen_down=[True, False, True],
    )
    with pytest.raises(ValueError, match="exactly 3 pen-down stretches, got 2"):
        drawing_steps(plan)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(pen_radius=-0.001), "DrawingParams.pen_radius"),
        (dict(pen_stiffness=0.0), "DrawingParams.pen_stiffness"),
        (dict(pen_stiffness=np.nan), "DrawingParams.pen_stiffness"),
        (dict(pen_friction=-0.1), "DrawingParams.pen_friction"),
        (dict(hover_height=-0.03), "DrawingParams.hover_height"),
        (dict(press_depth=0.05), "DrawingParams.press_depth"),
    ],
)
def test_bad_parameters_name_the_field(change, message):
    with pytest.raises(ValueError, match=message):
        DrawingParams(**change)
    params = DrawingParams()
    for name, value in change.items():
        setattr(params, name, value)
    with pytest.raises(ValueError, match=message):
        default_drawing_plan(params)


def test_scene_refuses_bad_plants_and_poses(product):
    continuous = MultibodyPlant(0.0)
    with pytest.raises(ValueError, match="discrete plant"):
        add_drawing_scene(continuous, add_baxter_arm(continuous))
    no_geometry = MultibodyPlant(1e-3)
    no_geometry.set_contact_model(ContactModel.kPoint)
    with pytest.raises(ValueError, match="SceneGraph"):
        add_drawing_scene(no_geometry, add_baxter_arm(no_geometry))
    # The contact model is chosen, not left to the hydroelastic fallback.
    for model in ("hydroelastic_with_fallback", "hydroelastic"):
        builder = DiagramBuilder()
        config = MultibodyPlantConfig(time_step=1e-3, contact_model=model)
        plant, _ = AddMultibodyPlant(config, builder)
        with pytest.raises(ValueError, match="drawing scene needs point contact"):
            add_drawing_scene(plant, add_baxter_arm(plant))
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(product.plant, builder)
    arm = add_baxter_arm(plant)
    tilted = RigidTransform(RollPitchYaw(0.0, 0.2, 0.0), [0.6, -0.8, 0.1])
    with pytest.raises(ValueError, match="only turn the sheet about world z"):
        add_drawing_scene(plant, arm, X_WT=tilted)
    with pytest.raises(ValueError, match="only turn the sheet about world z"):
        default_drawing_plan(X_WT=tilted)
    plant.Finalize()
    with pytest.raises(ValueError, match="before plant.Finalize"):
        add_drawing_scene(plant, arm)
    # Drake's own default (time step 0 aside) is not point contact: a bare plant is refused.
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    with pytest.raises(ValueError, match="point contact"):
        add_drawing_scene(plant, add_baxter_arm(plant))


def test_params_load_from_yaml():
    params = yaml_load_typed(schema=DrawingParams, data="hover_height: 0.04\n")
    np.testing.assert_allclose(
        default_drawing_plan(params).points[0], np.add(DEFAULT_POSITION, [0, 0, 0.04])
    )
    bad = yaml_load_typed(schema=DrawingParams, data="pen_radius: -0.002\n")
    with pytest.raises(ValueError, match="DrawingParams.pen_radius"):
        add_drawing_scene(MultibodyPlant(1e-3), None, params=bad)


def test_plan_follower_feeds_the_plan_to_clik(product):
    with pytest.raises(ValueError, match="sample_period"):
        build_plan_follower(product, gain=GAIN, sample_period=0)
    follower = build_plan_follower(product, gain=GAIN)
    plan = follower.plan
    assert plan.end_time == product.task_plan().end_time
    source = follower.diagram.GetSubsystemByName("plan")
    context = source.CreateDefaultContext()
    # The 5 ms linear interpolation of the minimum-jerk plan, and the end point held after it.
    for t in np.linspace(0.0, plan.end_time + 1.0, 157):
        context.SetTime(t)
        p = source.get_output_port().Eval(context)
        np.testing.assert_allclose(p, plan.position(min(t, plan.end_time)), atol=2e-5)
    # ... into the station's CLIK, at the constant gain.
    station = follower.diagram.GetSubsystemByName("station")
    assert follower.diagram.AreConnected(source.get_output_port(), station.GetInputPort("p_WE_desired"))
    root = follower.diagram.CreateDefaultContext()
    pd = station.GetSubsystemByName("pd")
    assert pd.gain_input.Eval(pd.GetMyContextFromRoot(root))[0] == GAIN
