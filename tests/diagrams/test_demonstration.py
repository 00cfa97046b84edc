"""The teleoperated demonstration loop, simulated through Drake at small scale."""

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import MeshcatVisualizer
from pydrake.math import RotationMatrix
from pydrake.systems.analysis import Simulator

from hemg_drake.diagrams.demonstration import (
    build_demonstration_diagram,
    demonstration_from_logs,
    record_demonstration,
    operator_plan,
    run_demonstration,
    seed_context,
)
from hemg_drake.diagrams.station import make_slave_station
from hemg_drake.diagrams.visualization import Visualization
from hemg_drake.emg.gain import VariableGain
from hemg_drake.emg.sources import MYO_PERIOD
from hemg_drake.learning.demos import tool_quaternions
from hemg_drake.robots.baxter import JOINT_NAMES
from hemg_drake.scenario import load_scenario, parse_scenario, shipped_scenario

# Free space: the scene frame on the tool's home point; 10 cm up-forward-left from it, then
# down-back-right (plan points in the scene frame T); the shipped scenarios' k_max.
FREE_SPACE = """
task: cotter_pin
scene: {position: [0.64, -0.84, 0.12]}
duration: 2.6
plan:
  times: [0.3, 1.3, 2.3]
  points: [[0.0, 0.0, 0.0], [0.06, 0.06, 0.06], [-0.03, -0.05, -0.03]]
  kinds: [free, forceful]
emg: {k_max: 200.0}
"""


def distance_to_path(points, path):
    """Distance of each point, shape (n, 3), to the polyline ``path``, shape (m, 3)."""
    a, b = path[:-1], path[1:]
    ab = b - a
    t = np.einsum("nmk,mk->nm", points[:, None] - a, ab) / np.maximum((ab**2).sum(1), 1e-300)
    closest = a + np.clip(t, 0.0, 1.0)[..., None] * ab
    return np.linalg.norm(points[:, None] - closest, axis=2).min(axis=1)


def simulate(scenario, seed, **kwargs):
    """Build and run one demonstration; also the plant's context at the end."""
    built = build_demonstration_diagram(scenario, **kwargs)
    simulator = Simulator(built.diagram)
    seed_context(built, simulator.get_mutable_context(), seed)
    simulator.AdvanceTo(scenario.duration)
    root = simulator.get_context()
    demo = demonstration_from_logs(
        built.logger.FindLog(root), built.emg_logger.FindLog(root), seed
    )
    return built, demo, built.plant.GetMyContextFromRoot(root)


@pytest.fixture(scope="module")
def free_space():
    scenario = parse_scenario(FREE_SPACE)
    built = build_demonstration_diagram(scenario, scene=False)
    return scenario, run_demonstration(built, 3)


def test_free_space_slave_follows_the_mapped_master(free_space):
    scenario, demo = free_space
    assert len(demo) == 261 and demo.time[-1] == pytest.approx(2.6)
    p_WE_desired = scenario.workspace_mapping().master_to_slave(demo.p_MS)
    travel = np.ptp(p_WE_desired, axis=0)
    assert np.linalg.norm(travel) > 0.1  # the operator really moved the master
    # Reached: 5.0 mm at the same instant (the slave lags during the fastest motion, about
    # 0.3 m/s), 2.4 mm RMS; 4.3 mm from the path itself, lag aside; 0.1 mm once at rest.
    error = np.linalg.norm(demo.p_WE - p_WE_desired, axis=1)
    assert error.max() < 0.006 and np.sqrt(np.mean(error**2)) < 0.003
    assert distance_to_path(demo.p_WE, p_WE_desired).max() < 0.005
    assert error[demo.time > 2.4].max() < 0.0005
    # v_WE agrees with the logged positions' central differences (an independent check).
    dt = np.diff(demo.time)[0]
    v_numeric = (demo.p_WE[2:] - demo.p_WE[:-2]) / (2 * dt)
    assert np.abs(v_numeric - demo.v_WE[1:-1]).max() < 0.02
    assert np.abs(demo.v_WE).max() > 0.1
    # Free space: nothing pushes on the tool.
    assert not np.any(demo.f_WE)


def check_logged_arm(station, demo):
    """The logged q and R_WE against the plant's forward kinematics: q set joint by joint
    (by name, in JOINT_NAMES order) in a fresh plant context puts the tool frame at the
    logged p_WE, turned by the logged R_WE; the quaternions are unit and the same rotation."""
    plant, frame = station.plant, station.arm.tool_frame
    context = plant.CreateDefaultContext()
    joints = [plant.GetJointByName(name) for name in JOINT_NAMES]
    world = plant.world_frame()
    quats = tool_quaternions([demo])[0]
    assert demo.q.shape == (len(demo), 7) and demo.R_WE.shape == (len(demo), 3, 3)
    for k in range(len(demo)):
        for joint, angle in zip(joints, demo.q[k], strict=True):
            joint.set_angle(context, angle)
        p_WE = plant.CalcPointsPositions(context, frame, np.zeros(3), world)[:, 0]
        R_WE = plant.CalcRelativeRotationMatrix(context, world, frame).matrix()
        np.testing.assert_allclose(demo.p_WE[k], p_WE, rtol=0, atol=1e-9)
        np.testing.assert_allclose(demo.R_WE[k], R_WE, rtol=0, atol=1e-12)
        from_quaternion = RotationMatrix(Quaternion(quats[k])).matrix()
        np.testing.assert_allclose(from_quaternion, R_WE, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(quats, axis=1), 1.0, atol=1e-14)
    assert np.abs(np.diff(quats, axis=0)).max() < 0.05  # one side: no sign flips
    assert np.ptp(demo.q, axis=0).max() > 0.05  # the arm really moved


def test_logged_joints_and_tool_rotation_are_the_plants_kinematics(free_space):
    scenario, demo = free_space
    check_logged_arm(make_slave_station(scenario, scene=False), demo)


def test_logged_reference_is_the_mapped_master_without_delay(free_space):
    scenario, demo = free_space
    assert scenario.mapping.delay_steps == 0
    expected = scenario.workspace_mapping().master_to_slave(demo.p_MS)
    np.testing.assert_allclose(demo.p_WE_desired, expected, atol=1e-12)


def test_logged_reference_is_what_the_clik_received_after_the_delay():
    # 20 master samples (20 ms, two log periods) of transport delay: the reference the CLIK
    # got at t is the stylus mapped at t - 20 ms.
    scenario = parse_scenario(FREE_SPACE).replaced(["duration=0.9", "mapping.delay_steps=20"])
    built = build_demonstration_diagram(scenario, scene=False)
    demo = run_demonstration(built, 3)
    mapped = scenario.workspace_mapping().master_to_slave(demo.p_MS)
    moving = np.linalg.norm(np.diff(mapped, axis=0), axis=1).max()
    assert moving > 1e-3  # the stylus moves more than 1 mm per log period
    np.testing.assert_allclose(demo.p_WE_desired[2:], mapped[:-2], atol=1e-3 * moving)
    assert np.abs(demo.p_WE_desired[2:] - mapped[2:]).max() > 0.5 * moving
    # ... and it is what the CLIK reads: its input at 0.6 s in a second run of the same seed
    # (a logger sees its ports as a context after AdvanceTo(t) does: before t's updates).
    again = build_demonstration_diagram(scenario, scene=False)
    simulator = Simulator(again.diagram)
    seed_context(again, simulator.get_mutable_context(), 3)
    simulator.AdvanceTo(0.6)
    root = simulator.get_context()
    clik = again.station.diagram.GetSubsystemByName("clik")
    master = again.diagram.GetSubsystemByName("master")
    received = clik.GetInputPort("p_WE_desired").Eval(clik.GetMyContextFromRoot(root))
    np.testing.assert_array_equal(received, demo.p_WE_desired[60])
    now = master.GetOutputPort("p_MS").Eval(master.GetMyContextFromRoot(root))
    assert np.linalg.norm(received - scenario.workspace_mapping().master_to_slave(now)) > 1e-4


def test_gain_follows_the_operators_effort(free_space):
    scenario, demo = free_space
    plan = scenario.task_plan()
    assert demo.gain.min() >= scenario.emg.k_min and demo.gain.max() <= scenario.emg.k_max
    free = (demo.time > 0.3) & (demo.time < 1.3)
    forceful = (demo.time > 1.5) & (demo.time < 2.3)
    assert plan.kinds == ("free", "forceful")
    assert demo.gain[forceful].mean() > 1.5 * demo.gain[free].mean()
    assert demo.activation[forceful].mean() > demo.activation[free].mean()
    # The envelope and the gain rise and fall together (eq. 22 is monotone).
    assert np.corrcoef(demo.envelope, demo.gain)[0, 1] > 0.8


def test_the_logged_200_hz_semg_is_what_the_envelope_read(free_space):
    scenario, demo = free_space
    # 200 Hz from t = 0 to the end: sample k at k / 200 s.
    assert len(demo.emg) == round(scenario.duration / MYO_PERIOD)
    np.testing.assert_allclose(demo.emg_time, np.arange(len(demo.emg)) * MYO_PERIOD)
    assert np.all(demo.emg == np.round(demo.emg)) and np.abs(demo.emg).max() <= 128
    assert len(demo.muscle_activation) == len(demo.emg)
    assert 0.0 <= demo.muscle_activation.min() and demo.muscle_activation.max() <= 1.0
    # Eqs. 1-2 offline, on the logged samples: log sample m (at 10 m ms) holds the envelope
    # of sEMG samples 0 .. 2m - 1 (the envelope updates half a MYO period after its sample).
    # Brute force, written here (eqs. 1-2: the RMS of the channel sum over the last L
    # samples, zeros before the first), not the library's moving_rms the system shares.
    total = demo.emg.sum(axis=1)
    L = scenario.emg.window
    offline = np.array([np.sqrt(np.sum(total[max(0, k - L + 1) : k + 1] ** 2) / L)
                        for k in range(len(total))])  # fmt: skip
    m = np.arange(1, len(demo))
    np.testing.assert_allclose(demo.envelope[m], offline[2 * m - 1], rtol=1e-12, atol=1e-12)
    assert demo.envelope[0] == 0.0
    # The operator's activation drove the source: higher in the forceful segment.
    t = demo.emg_time
    forceful = demo.muscle_activation[(t > 1.5) & (t < 2.3)].mean()
    assert forceful > 1.5 * demo.muscle_activation[(t > 0.5) & (t < 1.3)].mean()


def test_the_pd_gain_is_the_variable_gain_output_computed_at_200_hz(monkeypatch):
    calls = []
    calc_gain = VariableGain._calc_gain

    def counted(self, context, output):
        calls.append(context.get_time())
        calc_gain(self, context, output)

    monkeypatch.setattr(VariableGain, "_calc_gain", counted)
    scenario = parse_scenario(FREE_SPACE).replaced(["duration=1.0"])
    built = build_demonstration_diagram(scenario, scene=False)
    diagram, station = built.diagram, built.station.diagram
    # No hold between the gain law and the PD: the station's gain input is its output.
    names = {system.get_name() for system in diagram.GetSystems()}
    names |= {system.get_name() for system in station.GetSystems()}
    assert "gain_hold" not in names
    variable_gain = diagram.GetSubsystemByName("variable_gain")
    gain_port = diagram.GetSubsystemByName("station").GetInputPort("gain")
    assert diagram.AreConnected(variable_gain.get_gain_output_port(), gain_port)
    pd = station.GetSubsystemByName("pd")
    locators = station.GetInputPortLocators(station.GetInputPort("gain").get_index())
    assert locators == [(pd, pd.gain_input.get_index())]
    simulator = Simulator(diagram)
    simulator.Initialize()
    calls.clear()
    simulator.AdvanceTo(1.0)
    # Recomputed when the 200 Hz envelope changes, not at each of the 1000 plant steps.
    assert 195 <= len(calls) <= 205
    assert len(np.unique(np.round(calls, 9))) == len(calls)
    # The PD reads exactly the gain law's output.
    root = simulator.get_context()
    k = variable_gain.get_gain_output_port().Eval(variable_gain.GetMyContextFromRoot(root))
    np.testing.assert_array_equal(pd.gain_input.Eval(pd.GetMyContextFromRoot(root)), k)


def test_same_seed_same_demonstration_bitwise():
    scenario = parse_scenario(FREE_SPACE).replaced(["duration=0.8"])
    first = record_demonstration(scenario, 11, scene=False)
    again = record_demonstration(scenario, 11, scene=False)
    other = record_demonstration(scenario, 12, scene=False)
    for name in (
        "time", "p_WE", "v_WE", "p_MS", "p_WE_desired", "envelope", "activation", "gain",
        "f_WE", "emg_time", "emg", "muscle_activation", "q", "R_WE",
    ):  # fmt: skip
        assert getattr(first, name).tobytes() == getattr(again, name).tobytes(), name
    assert not np.array_equal(first.envelope, other.envelope)
    assert not np.array_equal(first.emg, other.emg)
    assert not np.array_equal(first.p_MS, other.p_MS)


def test_diagram_structure_and_bad_input():
    scenario = parse_scenario(FREE_SPACE)
    built = build_demonstration_diagram(scenario, scene=False)
    for name in (
        "station", "operator", "master", "workspace_map", "emg_source", "envelope",
        "variable_gain", "force_feedback", "logger", "emg_logger",
    ):  # fmt: skip
        assert built.diagram.HasSubsystemNamed(name), name
    for name in ("plant", "scene_graph", "clik", "pd", "tool_point"):
        assert built.station.diagram.HasSubsystemNamed(name), name
    assert built.scene is None
    assert not np.array_equal(operator_plan(scenario, 0).points, scenario.task_plan().points)
    assert not any(isinstance(s, MeshcatVisualizer) for s in built.station.diagram.GetSystems())
    live = build_demonstration_diagram(scenario, scene=False, visualization=Visualization())
    assert any(isinstance(s, MeshcatVisualizer) for s in live.station.diagram.GetSystems())
    with pytest.raises(ValueError, match="seed"):
        run_demonstration(built, -1)
    far = scenario.replaced(["scene.position=[2.5, 0.0, 0.0]"])
    with pytest.raises(ValueError, match="out of the arm's reach"):
        build_demonstration_diagram(far, scene=False)
    with pytest.raises(ValueError, match="duration"):
        run_demonstration(built, 0, duration=-1.0)


def test_building_does_not_simulate():
    scenario = parse_scenario(FREE_SPACE)
    built = build_demonstration_diagram(scenario)
    context = built.diagram.CreateDefaultContext()
    assert context.get_time() == 0.0
    plant_context = built.plant.GetMyContextFromRoot(context)
    q = built.plant.GetPositions(plant_context, built.station.arm.model_instance)
    np.testing.assert_array_equal(q, built.station.q0)
    assert built.scene.pin_displacement(plant_context) == 0.0


def test_calibration_shorter_than_the_window_is_refused():
    # 0.05 s of the MYO's 200 Hz is 10 samples, fewer than L_win = 20: no envelope to calibrate.
    with pytest.raises(ValueError, match="emg.calibration_duration' gives 10 samples.*window.*20"):
        parse_scenario(FREE_SPACE.replace("emg: {k_max: 200.0}", "emg: {k_max: 200.0, calibration_duration: 0.05}"))


@pytest.fixture(scope="module")
def pin_scenario():
    return load_scenario(shipped_scenario("cotter_pin"), overrides=["duration=3.0"])


def test_cotter_pin_comes_out_with_the_emg_gain(pin_scenario):
    built, demo, plant_context = simulate(pin_scenario, 1)
    assert built.scene.pin_out(plant_context)
    check_logged_arm(built.station, demo)  # with the pin's joint in the plant
    # The operator tensed up to pull: the gain peaks high, and the pin resisted (felt force).
    assert demo.gain.max() > 100
    assert demo.f_WE[:, 2].min() < -20


def test_cotter_pin_stays_in_with_a_constant_low_gain(pin_scenario):
    # k_max barely above k_min: the gain is 10 whatever the muscles do.
    scenario = pin_scenario.replaced(["emg.k_min=10.0", "emg.k_max=10.01"])
    built, demo, plant_context = simulate(scenario, 1)
    assert np.ptp(demo.gain) <= 0.01
    assert not built.scene.pin_out(plant_context)
    assert built.scene.pin_displacement(plant_context) < 0.005
    # The operator did ask for the pull: the master went up by the plan's travel.
    assert np.ptp(scenario.workspace_mapping().master_to_slave(demo.p_MS)[:, 2]) > 0.04


def test_position_error_feedback_pulls_the_stylus_back_to_a_held_slave(pin_scenario):
    # The paper's master PD (Table I: K_pm = K_dm = 50) in the whole diagram: the pin holds
    # the slave (K = 10), so the stylus that the operator pushed up is pulled back down.
    scenario = pin_scenario.replaced(
        ["duration=2.0", "feedback.mode=position_error", "emg.k_min=10.0", "emg.k_max=10.01"]
    )
    built = build_demonstration_diagram(scenario)
    simulator = Simulator(built.diagram)
    seed_context(built, simulator.get_mutable_context(), 1)
    simulator.AdvanceTo(scenario.duration)
    root = simulator.get_context()
    assert not built.scene.pin_out(built.plant.GetMyContextFromRoot(root))
    feedback = built.diagram.GetSubsystemByName("force_feedback")
    station = built.diagram.GetSubsystemByName("station")
    master = built.diagram.GetSubsystemByName("master")

    def port(system, name):
        return system.GetOutputPort(name).Eval(system.GetMyContextFromRoot(root))

    mapping = scenario.workspace_mapping()
    gap = mapping.slave_to_master(port(station, "p_WE")) - port(master, "p_MS")
    gap_rate = mapping.velocity_to_master(port(station, "v_WE")) - port(master, "v_MS")
    expected = 50.0 * gap + 50.0 * gap_rate
    assert gap[1] < -0.005  # the stylus is more than 5 mm above where the slave is held
    motor_force = port(feedback, "motor_force")
    limit = scenario.feedback.peak_force
    np.testing.assert_allclose(
        motor_force, expected * min(1.0, limit / np.linalg.norm(expected)), rtol=1e-9
    )
    assert motor_force[1] < -1.0  # downwards (+y_M is up), towards the held slave


@pytest.mark.slow
def test_drawing_inks_three_strokes_with_high_stiffness_on_the_paper():
    from hemg_drake.tasks.plans import drawing_steps
    from hemg_drake.viz.ink import in_contact, ink_strokes

    scenario = load_scenario(shipped_scenario("drawing"))
    built = build_demonstration_diagram(scenario)
    plan = operator_plan(scenario, scenario.seed)  # what this seeded operator meant to draw
    demo = run_demonstration(built, scenario.seed, duration=plan.end_time)
    touching = in_contact(demo.f_WE)
    strokes = ink_strokes(demo.time, demo.p_WE, touching)
    assert len(strokes) == 3
    down = np.flatnonzero(np.diff(np.concatenate([[0], np.array(plan.pen_down, int), [0]])))
    for ink, first, stop in zip(strokes, down[0::2], down[1::2]):
        planned = plan.points[first : stop + 1, :2]  # the stroke's corners on the sheet
        assert distance_to_path(ink[:, :2], planned).max() < 0.005
        # ... and the ink covers the whole stroke: every corner is within 5 mm of the ink.
        assert distance_to_path(planned, ink[:, :2]).max() < 0.005
    steps = drawing_steps(plan)
    lifts = [(demo.time > steps[i]) & (demo.time < steps[i + 1]) for i in (1, 3)]
    drawn = [demo.gain[touching & (demo.time > steps[i]) & (demo.time < steps[i + 1])]
             for i in (0, 2, 4)]  # fmt: skip
    low = max(demo.gain[lift].mean() for lift in lifts)
    high = min(gain.mean() for gain in drawn)
    assert high > 1.5 * low


def test_plot_demonstrations_layouts(free_space):
    from hemg_drake.viz.figures import plot_demonstrations

    _, demo = free_space
    pin = plot_demonstrations([demo, demo], task="cotter_pin")
    assert len(pin.axes) == 6 and all(len(axes.lines) == 2 for axes in pin.axes)
    np.testing.assert_array_equal(pin.axes[5].lines[0].get_ydata(), demo.v_WE[:, 2])
    drawing = plot_demonstrations([demo], task="drawing")
    assert [axes.get_ylabel() for axes in drawing.axes][-1].startswith("stiffness K")
    np.testing.assert_array_equal(drawing.axes[3].lines[0].get_ydata(), demo.gain)
    with pytest.raises(ValueError, match="task"):
        plot_demonstrations([demo], task="welding")
    with pytest.raises(ValueError, match="at least one"):
        plot_demonstrations([], task="drawing")


def test_passive_force_feedback_reads_the_stylus_velocity():
    """In force mode the passivity controller needs v_MS: the builder connects it."""
    from hemg_drake.diagrams.demonstration import build_demonstration_diagram
    from hemg_drake.scenario import load_scenario, shipped_scenario

    scenario = load_scenario(
        shipped_scenario("cotter_pin"), overrides=["feedback.passivity=tdpa", "duration=0.05"]
    )
    built = build_demonstration_diagram(scenario)
    feedback = built.diagram.GetSubsystemByName("force_feedback")
    context = built.diagram.CreateDefaultContext()
    feedback_context = feedback.GetMyContextFromRoot(context)
    assert feedback.GetInputPort("v_MS").HasValue(feedback_context)
    feedback.GetOutputPort("motor_force").Eval(feedback_context)  # no unconnected input


def test_a_scenario_names_a_live_semg_source(monkeypatch):
    """emg.source: libemg puts a LiveEmgSource where the synthetic armband was, fed by the
    device (a fake LibEMG reader here) and read by the same envelope and gain law."""
    import numpy as np
    from pydrake.systems.analysis import Simulator

    from hemg_drake.diagrams.demonstration import build_demonstration_diagram
    from hemg_drake.emg import libemg
    from hemg_drake.emg.sources import LiveEmgSource
    from hemg_drake.scenario import load_scenario, shipped_scenario

    class Device:
        def __init__(self):
            self.count = 0

        def read_samples(self):
            self.count += 1
            return np.full((1, 8), 50.0)  # one strong sample per poll

    device = Device()
    monkeypatch.setattr(
        libemg, "libemg_emg_source",
        lambda *, tag, **_: (LiveEmgSource(device=device), None) if tag == "armband" else None,
    )  # fmt: skip
    scenario = load_scenario(
        shipped_scenario("cotter_pin"),
        overrides=["emg.source=libemg", "emg.libemg_tag=armband", "duration=0.2"],
    )
    built = build_demonstration_diagram(scenario)
    source = built.diagram.GetSubsystemByName("emg_source")
    assert isinstance(source, LiveEmgSource) and source.num_input_ports() == 0
    simulator = Simulator(built.diagram)
    simulator.AdvanceTo(0.2)
    gain = built.diagram.GetSubsystemByName("variable_gain")
    k = gain.get_gain_output_port().Eval(gain.GetMyContextFromRoot(simulator.get_context()))
    assert device.count >= 40 and k[0] > scenario.emg.k_min  # the live samples set the gain
