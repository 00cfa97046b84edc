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


def brute_force(demo, margin, distance=0.005, fraction=0.3):
    """Every sample tested one by one, from the start and from the end: active if it is
    more than ``distance`` from that end's sample or its gain is above the rest level (the
    sorted gains' 10th percentile, interpolated by hand) by more than the fraction."""
    k = sorted(demo[:, 6])
    rank = 0.1 * (len(k) - 1)
    low = int(rank)
    rest = k[low] + (rank - low) * (k[min(low + 1, len(k) - 1)] - k[low])
    level = rest + fraction * (k[-1] - k[0])

    def active(i, end):
        gap = sum((demo[i, d] - demo[end, d]) ** 2 for d in range(3)) ** 0.5
        return gap > distance or demo[i, 6] > level

    first = next(i for i in range(len(demo)) if active(i, 0))
    last = next(i for i in reversed(range(len(demo))) if active(i, -1))
    return max(first - margin, 0), min(last + 1 + margin, len(demo))


@pytest.mark.parametrize("lead, move, hold_k, tail", [
    (50, 100, 30, 80), (1, 40, 0, 3), (130, 60, 10, 5), (5, 80, 40, 200)])
def test_the_span_is_the_motion_and_stiffening_plus_the_margin(lead, move, hold_k, tail):
    demo = take(lead, move, hold_k, tail)
    # Closed form: 1 mm a sample, so 5 mm passed 5 samples after the first moving one (6 mm);
    # the last active sample is the last stiffened one, or without a hold the last still
    # 6 mm short of the end.
    last = lead + move + hold_k - 1 if hold_k else lead + move - 7
    expected = (max(lead + 5 - 20, 0), min(last + 1 + 20, len(demo)))
    assert active_span(demo) == expected == brute_force(demo, 20)


def test_a_stiffening_before_any_motion_counts_and_idle_takes_stay_whole():
    demo = take(50, 60, 0, 50)
    demo[40:50, 6] = 100.0  # a squeeze 10 samples before the hand moves
    assert active_span(demo, margin=0) == (40, 104) == brute_force(demo, 0)
    noisy = demo.copy()
    noisy[:40, 6] += 25.0 * (np.arange(40) % 2)  # rest noise of 25 % of the range: idle
    assert active_span(noisy, margin=0) == (40, 104)
    still = np.zeros((30, 7))
    assert active_span(still) == (0, 30)


def test_trim_cuts_each_take_and_none_keeps_them():
    demos = [take(50, 100, 30, 80), take(10, 50, 5, 300)]
    cut, spans = aligned(demos, "trim")
    assert spans == [(35, 200), (0, 85)]
    for demo, piece, (b, e) in zip(demos, cut, spans):
        np.testing.assert_array_equal(piece, demo[b:e])
    same, whole = aligned(demos, "none")
    assert whole == [(0, 260), (0, 365)] and all(a is b for a, b in zip(same, demos))
    with pytest.raises(ValueError, match="align must be one of"):
        aligned(demos, "dtw?")
