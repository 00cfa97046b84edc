"""learning.align "trim": each demonstration cut to its active span, against closed-form spans
of synthetic takes and a brute-force scan."""

import numpy as np
import pytest

from hemg_drake.learning.align import active_span, aligned


def take(lead, move, hold_k, tail, *, k_rest=10.0, k_high=100.0):
    """[x, xdot, k] of a take: ``lead`` idle samples, ``move`` samples at 0.1 m/s along x,
    ``hold_k`` still samples stiffened to k_high, ``tail`` idle samples at rest."""
    speed = np.concatenate([np.zeros(lead), np.full(move, 0.1), np.zeros(hold_k + tail)])
    x = np.cumsum(speed) * 0.01
    k = np.concatenate([np.full(lead + move, k_rest), np.full(hold_k, k_high),
                        np.full(tail, k_rest)])  # fmt: skip
    zeros = np.zeros_like(x)
    return np.column_stack([x, zeros, zeros, speed, zeros, zeros, k])


def brute_force(demo, margin, fraction=0.05):
    """Every sample tested one by one: active if its speed or its gain (against the gain at
    the nearer end it is scanned from) is off by more than the fraction."""
    speed = [float(np.sqrt(np.sum(row[3:6] ** 2))) for row in demo]
    k = demo[:, 6]
    top, spread = max(speed), k.max() - k.min()
    first = next(i for i in range(len(demo))
                 if speed[i] > fraction * top or abs(k[i] - k[0]) > fraction * spread)
    last = next(i for i in reversed(range(len(demo)))
                if speed[i] > fraction * top or abs(k[i] - k[-1]) > fraction * spread)
    return max(first - margin, 0), min(last + 1 + margin, len(demo))


@pytest.mark.parametrize("lead, move, hold_k, tail", [
    (50, 100, 30, 80), (0, 40, 0, 0), (130, 60, 10, 5), (5, 80, 40, 200)])
def test_the_span_is_the_motion_and_stiffening_plus_the_margin(lead, move, hold_k, tail):
    demo = take(lead, move, hold_k, tail)
    # Closed form: active from the first moving sample to the last stiffened one.
    expected = (max(lead - 20, 0), min(lead + move + hold_k + 20, len(demo)))
    assert active_span(demo) == expected == brute_force(demo, 20)


def test_a_stiffening_before_any_motion_counts_and_idle_takes_stay_whole():
    demo = take(50, 60, 0, 50)
    demo[40:50, 6] = 100.0  # a squeeze 10 samples before the hand moves
    assert active_span(demo, margin=0) == (40, 110) == brute_force(demo, 0)
    still = np.zeros((30, 7))
    assert active_span(still) == (0, 30)


def test_trim_cuts_each_take_and_none_keeps_them():
    demos = [take(50, 100, 30, 80), take(10, 50, 5, 300)]
    cut, spans = aligned(demos, "trim")
    assert spans == [(30, 200), (0, 85)]
    for demo, piece, (b, e) in zip(demos, cut, spans):
        np.testing.assert_array_equal(piece, demo[b:e])
    same, whole = aligned(demos, "none")
    assert whole == [(0, 260), (0, 365)] and all(a is b for a, b in zip(same, demos))
    with pytest.raises(ValueError, match="align must be one of"):
        aligned(demos, "dtw?")
