"""Worlds that differ from the demonstrations' and the stiffness policies of the study
(docs/studies.md): the block's contact, the moved sheet and fixture, the push in the
reproduction, and the gain sources (constant, demonstrated) checked against hand values."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from hemg_drake.diagrams.reproduction import build_reproduction_diagram, run_reproduction
from hemg_drake.diagrams.station import make_slave_station
from hemg_drake.scenario import Scenario, load_scenario, shipped_scenario
from hemg_drake.tasks.cotter_pin import DEFAULT_POSITION

START = np.array(DEFAULT_POSITION)


def _held_station(scenario, reference, gain=50.0, duration=0.3):
    """The station of ``scenario`` holding ``reference`` at ``gain`` for ``duration``."""
    station = make_slave_station(scenario)
    builder = DiagramBuilder()
    slave = builder.AddSystem(station.diagram)
    for value, port in ((reference, "p_WE_desired"), ([gain], "gain")):
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value, dtype=float)))
        builder.Connect(source.get_output_port(), slave.GetInputPort(port))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(duration)
    return station, slave, simulator


@pytest.fixture(scope="module")
def drawing():
    return load_scenario(shipped_scenario("drawing"))


def test_the_block_is_hit_by_the_pen_and_feels_its_force(drawing):
    start = drawing.task_plan().points[0]  # hover_height (3 cm) above the sheet's centre
    # A 2 cm block under the pen, its top 1 mm below the tip; the reference 5 mm into it.
    blocked = drawing.replaced(["scene.block.size=[0.04, 0.04, 0.02]",
                                "scene.block.position=[0.0, 0.0, 0.019]"])  # fmt: skip
    _, slave, simulator = _held_station(blocked, start - [0.0, 0.0, 0.005])
    context = slave.GetMyContextFromRoot(simulator.get_context())
    f_block = slave.GetOutputPort("f_block").Eval(context)
    f_WE = slave.GetOutputPort("f_WE").Eval(context)
    p_WE = slave.GetOutputPort("p_WE").Eval(context)
    assert f_block[2] < -1.0  # pressed down
    # Newton's third law: the pen (on the hand) feels the opposite force.
    np.testing.assert_allclose(f_WE, -f_block, atol=1e-9)
    # Stopped on the block's top, 1 mm below the start, pressing into the pen's compliant
    # tip (1e4 N/m: under a millimetre at these forces), not 5 mm through.
    top = start[2] - 0.001
    assert top - 0.001 < p_WE[2] < top
    # Without the block the same reference goes through where it stood, with no port.
    station, slave, simulator = _held_station(drawing, start - [0.0, 0.0, 0.005])
    assert not slave.HasOutputPort("f_block")
    p_free = slave.GetOutputPort("p_WE").Eval(slave.GetMyContextFromRoot(simulator.get_context()))
    assert p_free[2] < start[2] - 0.004


def test_the_sheet_offset_moves_the_sheet_not_the_plan(drawing):
    raised = drawing.replaced(["scene.drawing.sheet_offset=0.01"])
    np.testing.assert_array_equal(raised.task_plan().points, drawing.task_plan().points)
    station = make_slave_station(raised)
    np.testing.assert_allclose(station.scene.paper_center,
                               drawing.X_WT().translation() + [0.0, 0.0, 0.01])  # fmt: skip
    # Held 2.5 cm above the planned sheet (5 mm above the raised one): touching nothing;
    # 5 mm lower (0.5 cm into the raised sheet) the pen presses.
    over = drawing.X_WT().translation() + [0.0, 0.0, 0.015]
    *_, simulator = _held_station(raised, over + [0.0, 0.0, 0.01])
    assert _pen_force(simulator) == 0.0
    *_, simulator = _held_station(raised, over - [0.0, 0.0, 0.01])
    assert _pen_force(simulator) > 1.0


def _pen_force(simulator):
    diagram = simulator.get_system()
    slave = next(s for s in diagram.GetSystems() if s.get_name() == "station")
    return float(np.linalg.norm(slave.GetOutputPort("f_WE").Eval(
        slave.GetMyContextFromRoot(simulator.get_context()))))  # fmt: skip


def test_the_fixture_offset_stretches_the_grasp_by_that_offset():
    pin = load_scenario(shipped_scenario("cotter_pin"))
    moved = pin.replaced(["scene.cotter_pin.fixture_offset=[0.0, 0.008, 0.0]"])
    np.testing.assert_array_equal(moved.task_plan().points, pin.task_plan().points)
    station = make_slave_station(moved)
    diagram = station.diagram
    context = diagram.CreateDefaultContext()
    diagram.GetInputPort("gain").FixValue(context, [10.0])
    diagram.GetInputPort("p_WE_desired").FixValue(context, pin.task_plan().points[0])
    # Hand value: the bushing (5000 N/m) stretched 8 mm across: 40 N pulling the tool +y.
    f_WE = diagram.GetOutputPort("f_WE").Eval(context)
    np.testing.assert_allclose(f_WE, [0.0, 40.0, 0.0], atol=0.05)


def _scenario(*changes):
    return Scenario().replaced(
        ["task=cotter_pin", "duration=0.5", "reproduction.weighting=temporal", *changes]
    )


@pytest.mark.parametrize("gain, applied", [(37.0, 37.0), (500.0, 100.0)])
def test_a_constant_gain_replaces_k_star_and_keeps_the_reference(model, gain, applied):
    constant = _scenario("reproduction.gain_source=constant",
                         f"reproduction.constant_gain={gain}")  # fmt: skip
    log = run_reproduction(build_reproduction_diagram(constant, model, scene=False)).log
    np.testing.assert_array_equal(log.k_star, applied)  # clipped to [k_min, k_max] = [10, 100]
    learnt = run_reproduction(build_reproduction_diagram(_scenario(), model, scene=False)).log
    assert np.ptp(learnt.k_star) > 10.0  # the learnt k* varies; the constant does not
    np.testing.assert_array_equal(log.x_star, learnt.x_star)
    with pytest.raises(ValueError, match="constant_gain"):
        _scenario("reproduction.gain_source=constant")


def test_the_demonstrated_gain_is_replayed_in_time(model):
    times, gain = np.array([0.0, 0.2, 0.5]), np.array([15.0, 95.0, 40.0])
    replayed = _scenario("reproduction.gain_source=demonstrated")
    log = run_reproduction(build_reproduction_diagram(
        replayed, model, scene=False, demonstrated_gain=(times, gain)), settle=False).log
    # Hand values of the straight pieces: 15 + 400 t until 0.2 s, then 95 - 550/3 (t - 0.2).
    expected = np.where(log.time <= 0.2, 15.0 + 400.0 * log.time,
                        95.0 - 550.0 / 3.0 * (log.time - 0.2))  # fmt: skip
    np.testing.assert_allclose(log.k_star, expected, rtol=1e-12)
    with pytest.raises(ValueError, match="demonstrated_gain"):
        build_reproduction_diagram(replayed, model, scene=False)


def test_the_push_reaches_the_arm_in_the_reproduction_but_not_the_settling(model):
    pushed = _scenario("reproduction.push.force=[0.0, 40.0, 0.0]", "reproduction.push.start=0.1",
                       "reproduction.push.duration=0.2")  # fmt: skip
    built = build_reproduction_diagram(pushed, model, scene=False)
    log = run_reproduction(built).log
    # (The samples at 0.1 s and 0.3 s sit on the push's edges, in floating point.)
    on = (log.time > 0.1 + 1e-6) & (log.time < 0.3 - 1e-6)
    off = (log.time < 0.1 - 1e-6) | (log.time > 0.3 + 1e-6)
    np.testing.assert_array_equal(log.f_push[on], [[0.0, 40.0, 0.0]] * int(on.sum()))
    np.testing.assert_array_equal(log.f_push[off], 0.0)
    plain = run_reproduction(build_reproduction_diagram(_scenario(), model, scene=False)).log
    y = log.p_WE[:, 1] - plain.p_WE[:, 1]
    np.testing.assert_allclose(y[log.time <= 0.1], 0.0, atol=1e-9)  # settled alike
    assert y[log.time <= 0.31].max() > 0.002  # pushed along +y
