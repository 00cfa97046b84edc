"""learning.align "trim": each demonstration cut to its active span, against closed-form spans
of synthetic takes and a brute-force scan."""

import numpy as np
import pytest

from hemg_drake.learning.align import active_span, aligned, reference_take, warped_onto
from hemg_drake.learning.dtw import dtw_path


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


def brute_dtw_cost(a, b):
    """The least summed Euclidean distance over every monotone path from (0, 0) to the end,
    enumerated one by one (each step advances a, b or both)."""
    best = np.inf

    def walk(i, j, total):
        nonlocal best
        total += np.linalg.norm(a[i] - b[j])
        if (i, j) == (len(a) - 1, len(b) - 1):
            best = min(best, total)
            return
        for di, dj in ((1, 1), (1, 0), (0, 1)):
            if i + di < len(a) and j + dj < len(b):
                walk(i + di, j + dj, total)

    walk(0, 0, 0.0)
    return best


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_dtw_path_is_the_least_cost_path_of_a_brute_force_search(seed):
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(5, 2)), rng.normal(size=(6, 2))
    index_a, index_b = dtw_path(a, b)
    steps = np.column_stack([np.diff(index_a), np.diff(index_b)])
    assert (index_a[0], index_b[0], index_a[-1], index_b[-1]) == (0, 0, 4, 5)
    assert all(tuple(s) in {(1, 1), (1, 0), (0, 1)} for s in steps)
    cost = np.linalg.norm(a[index_a] - b[index_b], axis=1).sum()
    assert cost == pytest.approx(brute_dtw_cost(a, b), rel=1e-12)


def curve_take(phase):
    """[x, xdot, k] along a planar S-curve at path parameter ``phase`` in [0, 1] (0.01 s
    samples); the gain a function of the place on the path, as a stiffening there would be."""
    x = np.column_stack([0.1 * phase, 0.03 * np.sin(2 * np.pi * phase), np.zeros_like(phase)])
    k = 10.0 + 90.0 * np.sin(np.pi * phase) ** 2
    return np.column_stack([x, np.gradient(x, 0.01, axis=0), k])


def test_a_known_time_warp_is_undone_onto_the_reference():
    reference = curve_take(np.linspace(0.0, 1.0, 400))
    # The same path with a pause, taken slowly then quickly, 1.5x longer: warped onto the
    # reference it lies on the reference's samples, to the warp's sampling resolution.
    u = np.linspace(0.0, 1.0, 600)
    halfway = np.where(u < 0.4, 0.5, 0.5 + 0.5 * (u - 0.4) / 0.6)  # a pause from 0.3 to 0.4
    phase = np.clip(np.where(u < 0.3, 0.5 * u / 0.3, halfway), 0, 1) ** 1.5
    warped = warped_onto(curve_take(phase), reference)
    assert warped.shape == reference.shape
    step = np.max(np.linalg.norm(np.diff(curve_take(phase)[:, :3], axis=0), axis=1))
    assert np.max(np.linalg.norm(warped[:, :3] - reference[:, :3], axis=1)) < step
    assert np.max(np.abs(warped[:, 6] - reference[:, 6])) < 1.5  # of a 90 range
    np.testing.assert_array_equal(warped_onto(reference, reference), reference)


def test_dtw_warps_every_take_onto_the_take_of_median_length():
    shapes = ((300, 1.0), (500, 2.0), (420, 0.7))  # samples, warp exponent
    takes = [curve_take(np.linspace(0, 1, n) ** e) for n, e in shapes]
    assert reference_take(takes) == 2 and reference_take(takes[:2]) == 0
    warped, spans = aligned(takes, "dtw")
    assert [w.shape for w in warped] == [(420, 7)] * 3
    assert spans == [(0, 300), (0, 500), (0, 420)]
    np.testing.assert_array_equal(warped[2], takes[2])
    for w in warped[:2]:
        assert np.max(np.linalg.norm(w[:, :3] - takes[2][:, :3], axis=1)) < 0.003
