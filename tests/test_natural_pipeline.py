"""End to end, small: three human-like takes of the cotter pin, learnt with the shipped
settings (chosen for natural takes, docs/learning.md) and reproduced, pull the pin out without
overshoot; "trim" cuts each take's idle lead-in to just before it stiffens, "dtw" warps each
onto the median-length take."""

import pytest

from hemg_drake.diagrams.demonstration import operator_plan
from hemg_drake.learning.align import active_span
from hemg_drake.pipeline import demonstrate, learn, learning_data, load_demonstrations, reproduce
from hemg_drake.scenario import load_scenario, shipped_scenario


def quiet(_line):
    pass


@pytest.mark.slow
def test_three_human_takes_learn_the_pin(tmp_path):
    # Tuning seeds 11-13 (hemg_drake/data/seeds.yaml): takes of 6.7, 2.5 and 4.3 s that
    # start after 1.8, 1.4 and 1.6 s of idle.
    scenario = load_scenario(shipped_scenario("cotter_pin"), overrides=[
        "operator.style=human", "num_demonstrations=3", "seed=11",
        "duration=9.5", "reproduction.num_heldout=0", "reproduction.start_offsets=[]",
    ])  # fmt: skip
    plans = [operator_plan(scenario, seed) for seed in scenario.seeds()]
    lengths = [p.end_time - p.start_time for p in plans]
    assert max(lengths) / min(lengths) > 2.0 and max(p.end_time for p in plans) < 9.0
    run = tmp_path / "run"
    demonstrate(scenario, run, replays=False, progress=quiet)
    demos, stored = load_demonstrations(run / "dataset.npz")
    trimmed = learning_data(demos, stored.replaced(["learning.align=trim"]))
    for demo, plan, kept, full in zip(demos, plans, trimmed, learning_data(demos, stored),
                                      strict=True):  # fmt: skip
        begin, end = active_span(full)
        assert kept.shape == full[begin:end].shape and end - begin < len(full)
        # The idle lead-in cut, to 0.2 s (the margin) before the hand moved or stiffened:
        # after the plan started (it rests on the ring first), before it pulls.
        assert plan.start_time - 0.2 <= demo.time[begin] <= plan.times[2]
    # "dtw": every take on the samples of the median-length one, which it keeps as it is.
    warped = learning_data(demos, stored.replaced(["learning.align=dtw"]))
    full = learning_data(demos, stored)
    middle = sorted(range(3), key=lambda c: len(full[c]))[1]
    assert all(w.shape == full[middle].shape for w in warped)
    assert (warped[middle] == full[middle]).all()
    learn(run, progress=quiet)
    metrics = reproduce(run, replay=False, progress=quiet)
    assert metrics["pin_out"] and metrics["success_checks"]["no overshoot"]
