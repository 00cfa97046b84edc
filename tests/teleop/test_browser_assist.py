"""The person's assist switch (the teleop page's A key): the browser master's ``assist_on``
by hand from input rows, an older inputs log read with the switch never pressed, and a
take re-driven from its log with the switch pressed mid-take (the arbitration's weight
falls to 0 by its filter, and the same log gives the same take bit for bit)."""

import math

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from hemg_drake.fileio import save_npz_atomic
from hemg_drake.scenario import load_scenario, shipped_scenario
from hemg_drake.teleop.browser import BrowserMaster
from hemg_drake.teleop.browser_inputs import (
    COLUMNS,
    COLUMNS_BEFORE_ASSIST,
    INPUTS_FORMAT,
    LoggedInputs,
    load_inputs,
)


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    """A hand-set 3-state HSMM along the cotter pin's pull (the assist diagram's test's)."""
    from assist.test_assist_diagram import model_path as hand_model

    return hand_model.__wrapped__(tmp_path_factory)


def rows_with_clicks(clicks):
    values = dict(zip(COLUMNS, [math.nan] * len(COLUMNS)))
    values.update(slider_x_mm=0.0, slider_y_mm=0.0, slider_z_mm=0.0, slider_activation=0.05,
                  gamepad_index=-1.0, end_clicks=0.0, connections=1.0)  # fmt: skip
    rows = []
    for c in clicks:
        values["assist_clicks"] = c
        rows.append([values[name] for name in COLUMNS])
    return np.array(rows)


def test_assist_on_toggles_with_each_click_from_the_first_sample():
    # Clicks counted from the first sample (3 there: a page that was clicked before the
    # take); NaN holds the switch.
    clicks = [3, 3, 4, 4, math.nan, 5, 7, 8]
    expected = [1, 1, 0, 0, 0, 1, 1, 0]
    rows = rows_with_clicks(clicks)
    times = 0.01 * np.arange(len(rows))
    master = BrowserMaster(source=LoggedInputs(times, rows), p_MS_initial=[0.0, 0.0, 0.0])
    simulator = Simulator(master)
    context = simulator.get_mutable_context()
    for name in ("p_MS", "v_MS", "feedback_force"):
        master.GetInputPort(name).FixValue(context, np.zeros(3))
    assert master.GetOutputPort("assist_on").Eval(context)[0] == 1.0  # before any sample
    seen = []
    for k in range(len(rows)):
        simulator.AdvanceTo(times[k] + 0.005)
        seen.append(master.GetOutputPort("assist_on").Eval(context)[0])
    assert seen == expected
    # The master's step law gives the same (what the page's log re-drives).
    state = list(master.initial_state)
    for row, on in zip(rows.tolist(), expected):
        state = master.step(row, state)
        assert state[15] == on


def test_an_inputs_log_without_the_switch_reads_as_never_pressed(tmp_path):
    rows = rows_with_clicks([0.0, 0.0])[:, : len(COLUMNS_BEFORE_ASSIST)]
    path = tmp_path / "old.npz"
    save_npz_atomic(path, format_version=np.array(INPUTS_FORMAT),
                    columns=np.array(COLUMNS_BEFORE_ASSIST), time=np.array([0.0, 0.01]),
                    wall_time=np.zeros(2), rows=rows, end_time=np.array(0.02),
                    end_reason=np.array("button"), seed=np.array(1),
                    scenario=np.array("x"))  # fmt: skip
    log = load_inputs(path)
    assert log.rows.shape == (2, len(COLUMNS))
    assert np.all(log.rows[:, COLUMNS.index("assist_clicks")] == 0.0)


def test_a_take_switches_the_assist_off_and_replays_bit_for_bit(model_path):
    """Mode fixed, W = 1, tau_w = 0.1 s, the arbitration updated every T (the master's
    period): the weight rises as 1 - (1 - T/tau)^k; the click logged at 0.5 s switches the
    assist off and it falls as w(0.5) (1 - T/tau)^k (by hand, to a step or two)."""
    from hemg_drake.diagrams.demonstration import build_demonstration_diagram, seed_context

    scenario = load_scenario(shipped_scenario("cotter_pin"), overrides=[
        "assist.mode=fixed", "assist.weight=1.0", f"assist.model={model_path}",
        "assist.weight_time_constant=0.1",
    ])  # fmt: skip
    n = 100  # 1 s of inputs at 10 ms
    times, rows = 0.01 * np.arange(n), rows_with_clicks([0.0] * 50 + [1.0] * 50)

    def run():
        def factory(*, scenario, mapping, p_MS_initial):
            return BrowserMaster(source=LoggedInputs(times, rows), p_MS_initial=p_MS_initial)

        built = build_demonstration_diagram(scenario, operator_factory=factory)
        simulator = Simulator(built.diagram)
        seed_context(built, simulator.get_mutable_context(), 3)
        simulator.AdvanceTo(0.99)
        context = simulator.get_context()
        log = built.assist_logger.FindLog(context)
        return log.sample_times(), log.data(), built.logger.FindLog(context).data()

    t, data, demo = run()
    weight = data[0]
    T, rate = scenario.master.period, scenario.master.period / 0.1
    before = np.searchsorted(t, 0.5 - 1e-9) - 1  # the last log sample before the click
    k = round(t[before] / T)
    assert 1.0 - (1.0 - rate) ** (k - 1) <= weight[before]
    assert weight[before] <= 1.0 - (1.0 - rate) ** (k + 1)
    w_click = 1.0 - (1.0 - rate) ** round(0.5 / T)
    off_steps = round((t[-1] - 0.5) / T)
    assert w_click * (1 - rate) ** (off_steps + 2) <= weight[-1]
    assert weight[-1] <= w_click * (1 - rate) ** (off_steps - 2)
    assert weight[-1] < 0.02  # off: today's teleop again
    # The same inputs, the same take (the switch is in the log).
    t2, data2, demo2 = run()
    assert np.array_equal(data, data2) and np.array_equal(demo, demo2)
