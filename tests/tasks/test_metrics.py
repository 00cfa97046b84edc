"""Reproduction metrics on synthetic data with known answers."""

import numpy as np
import pytest

from hemg_drake.tasks import metrics


def ramp(n, *, speed=1.0, offset=0.0):
    """[x, xdot, k] of a point moving along x at ``speed`` over n samples of 0.01 s."""
    t = 0.01 * np.arange(n)
    x = np.column_stack([offset + speed * t, np.zeros(n), np.zeros(n)])
    v = np.column_stack([np.full(n, speed), np.zeros(n), np.zeros(n)])
    return np.column_stack([x, v, 50.0 + 10.0 * t])


def test_dtw_path_undoes_a_time_warp():
    t = np.linspace(0.0, 1.0, 200)
    a = np.column_stack([np.sin(3 * t), t])
    warped = t**2  # the same path, traversed slowly then quickly
    b = np.column_stack([np.sin(3 * warped), warped])
    index_a, index_b = metrics.dtw_path(a, b)
    assert (index_a[0], index_b[0]) == (0, 0) and (index_a[-1], index_b[-1]) == (199, 199)
    assert np.all(np.diff(index_a) >= 0) and np.all(np.diff(index_b) >= 0)
    # Matched samples sit at the same place on the path, to the sampling resolution.
    assert np.max(np.abs(t[index_a] - warped[index_b])) < 0.02


def test_rmse_of_a_constant_offset_is_the_offset():
    reference = ramp(300)
    shifted = reference.copy()
    shifted[:, 1] += 0.002  # 2 mm beside the path, same velocity
    result = metrics.aligned_rmse(shifted, reference)
    assert result["position_rmse"] == pytest.approx(0.002, rel=1e-9)
    assert result["velocity_rmse"] == pytest.approx(0.0, abs=1e-12)


def test_rmse_ignores_timing_but_not_speed_errors():
    reference = ramp(300)
    # Same path, 1.5x slower but on the same samples' positions: DTW aligns it.
    slow = ramp(450, speed=1.0 / 1.5)
    result = metrics.aligned_rmse(slow, reference)
    assert result["position_rmse"] < 0.01 / 1.5  # within one sample's travel
    # The velocity error is the speed difference.
    assert result["velocity_rmse"] == pytest.approx(1.0 - 1.0 / 1.5, rel=1e-6)
    # Time normalisation compares the same fractions of time: the same path again (the two
    # end 3.3 mm apart, less than one reference sample's travel).
    plain = metrics.time_normalised_rmse(slow, [reference])
    assert plain["position_rmse"] < 0.004


def test_mean_demonstration_averages_aligned_demos():
    # Two demonstrations 2 mm either side of the path, one of them slower: the mean is the path.
    a, b = ramp(300), ramp(600, speed=0.5)
    a[:, 2] += 0.002
    b[:, 2] -= 0.002
    mean = metrics.mean_demonstration([a, b])
    assert mean.shape == a.shape
    np.testing.assert_allclose(mean[:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(mean[:, 0], a[:, 0], atol=0.006)


def test_stiffness_correlation():
    k = np.sin(np.linspace(0, 6, 100))
    assert metrics.stiffness_correlation(3 * k + 1, k) == pytest.approx(1.0)
    assert metrics.stiffness_correlation(-k, k) == pytest.approx(-1.0)
    assert metrics.stiffness_correlation(np.ones(100), k) is None
    # Along a path: the reproduction's samples are compared with their matched references.
    path = (np.arange(100), np.arange(100)[::-1])
    assert metrics.stiffness_correlation(k, k, path) == pytest.approx(
        np.corrcoef(k, k[::-1])[0, 1]
    )
    with pytest.raises(ValueError, match="differ in length"):
        metrics.stiffness_correlation(k, k[:50])


def test_force_statistics():
    force = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]])
    assert metrics.force_statistics(force) == {"peak": 5.0, "mean": 3.0}


def test_stroke_errors_split_into_shape_and_placement():
    line = np.column_stack([np.linspace(0, 0.1, 20), np.zeros(20)])
    # The demonstrations' mean is the line itself; the stroke lies 3 mm beside it, sampled
    # more densely (the resampling by arc length makes the sampling irrelevant).
    demos = [line + [0.0, 0.001], line - [0.0, 0.001]]
    stroke = np.column_stack([np.linspace(0, 0.1, 57), np.full(57, 0.003)])
    errors = metrics.stroke_errors(stroke, demos)
    assert errors["placement"] == pytest.approx(0.003, rel=1e-9)
    assert errors["rms"] == pytest.approx(0.003, rel=1e-9)
    assert errors["shape"] == pytest.approx(0.0, abs=1e-12)
    # A bent stroke: a shape error, and rms^2 = shape^2 + placement^2.
    bent = np.column_stack([np.linspace(0, 0.1, 57), 0.02 * np.sin(np.linspace(0, np.pi, 57))])
    errors = metrics.stroke_errors(bent, demos)
    assert errors["shape"] > 0.005
    assert errors["rms"] ** 2 == pytest.approx(errors["shape"] ** 2 + errors["placement"] ** 2)
    resampled = metrics.resample_by_arc_length(np.array([[0, 0], [1, 0], [1, 1]]), 5)
    np.testing.assert_allclose(resampled, [[0, 0], [0.5, 0], [1, 0], [1, 0.5], [1, 1]])


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: metrics.dtw_path(np.zeros((5, 2)), np.zeros((5, 3))), "2 columns"),
        (lambda: metrics.aligned_rmse(np.full((5, 7), np.nan), np.zeros((5, 7))), "NaN"),
        (lambda: metrics.mean_demonstration([]), "at least one"),
        (lambda: metrics.time_normalise(np.zeros((5, 2)), 1), "n_samples"),
        (lambda: metrics.force_statistics(np.zeros((5, 2))), "3 columns"),
        (lambda: metrics.resample_by_arc_length(np.zeros((5, 2))), "zero length"),
        (lambda: metrics.resample_by_arc_length(np.eye(2), 1), "n_samples"),
        (lambda: metrics.stroke_errors(np.eye(2), [np.eye(2)], n_samples=0), "n_samples"),
        (lambda: metrics.stroke_errors(np.eye(2), []), "at least one"),
        (lambda: metrics.stroke_errors(np.eye(2), [np.eye(3)]), "columns"),
        (lambda: metrics.aligned_rmse(np.zeros((1, 7)), np.zeros((5, 7))), "T >= 2"),
    ],
)
def test_bad_input_is_a_value_error(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_timing_error_is_the_rms_time_shift_of_a_delayed_copy():
    # A ramp and the same ramp held still for the first 20 samples: DTW matches the hold to
    # the ramp's first sample, so the shift grows to 20 samples, then stays: its RMS is
    # computed here from the path written out by hand.
    dt = 0.01
    ramp = np.column_stack([np.linspace(0.0, 1.0, 100), np.zeros(100)])
    held = np.vstack([np.repeat(ramp[:1], 20, axis=0), ramp])
    path = metrics.dtw_path(held, ramp)
    assert metrics.timing_error(path, dt) == pytest.approx(
        dt * np.sqrt(np.mean((path[0] - path[1]) ** 2))
    )
    # By hand: 20 samples matched to 0 with shifts 0..19, then 100 with shift 20.
    shifts = np.concatenate([np.arange(20), np.full(100, 20)])
    assert metrics.timing_error(path, dt) == pytest.approx(dt * np.sqrt(np.mean(shifts**2)))
    assert metrics.timing_error(metrics.dtw_path(ramp, ramp), dt) == 0.0
    with pytest.raises(ValueError, match="two index arrays"):
        metrics.timing_error((np.arange(3), np.arange(4)), dt)


def test_leave_one_out_measures_each_demonstration_against_the_others_mean():
    t = np.linspace(0.0, 1.0, 50)
    base = np.column_stack([t, 0 * t, 0 * t, np.ones_like(t), 0 * t, 0 * t, 0 * t])
    offsets = (0.0, 0.002, 0.004)
    speeds = (0.0, 0.01, 0.03)  # a sideways velocity channel, apart from the positions
    demos = [base + [0.0, dy, 0, 0, dv, 0, 0] for dy, dv in zip(offsets, speeds)]
    floor = metrics.leave_one_out(demos, 0.02)
    # Same timing: the others' mean lies at the mean of their offsets, straight across.
    for c, record in enumerate(floor):
        others = np.mean([dy for k, dy in enumerate(offsets) if k != c])
        others_v = np.mean([dv for k, dv in enumerate(speeds) if k != c])
        assert record["position_rmse"] == pytest.approx(abs(offsets[c] - others), abs=1e-12)
        assert record["spatial_position_rmse"] == pytest.approx(abs(offsets[c] - others), abs=1e-12)
        assert record["timing_error_s"] == 0.0
        assert record["velocity_rmse"] == pytest.approx(abs(speeds[c] - others_v), abs=1e-12)
        assert record["spatial_velocity_rmse"] == pytest.approx(abs(speeds[c] - others_v), abs=1e-12)
    with pytest.raises(ValueError, match="at least 2"):
        metrics.leave_one_out(demos[:1], 0.02)


def test_leave_one_out_after_dtw_matches_velocities_where_the_positions_match():
    # A moves along x one step per sample; B waits at the start for n samples, then moves
    # the same way. Their velocity channels are functions of position: 1 + x and 1 - x.
    # DTW matches equal positions: A[0] with B[0..n], then A[i] with B[n + i], so along the
    # path the velocity errors are 0 (n + 1 times) and 2 i (i = 1 .. n - 1), over 2 n pairs.
    n = 12
    x_a = np.arange(n, dtype=float)
    x_b = np.concatenate([np.zeros(n), np.arange(n, dtype=float)])

    def demo(x, v):
        zeros = np.zeros_like(x)
        return np.column_stack([x, zeros, zeros, v, zeros, zeros, zeros])

    a, b = demo(x_a, 1.0 + x_a), demo(x_b, 1.0 - x_b)
    expected = np.sqrt(np.sum((2.0 * np.arange(1, n)) ** 2) / (2 * n))
    for record in metrics.leave_one_out([a, b], 0.01):
        assert record["spatial_position_rmse"] == 0.0
        assert record["spatial_velocity_rmse"] == pytest.approx(expected, rel=1e-12)
        # Time-normalised, B's wait is compared with A's motion: another figure.
        assert abs(record["velocity_rmse"] - expected) > 0.5
