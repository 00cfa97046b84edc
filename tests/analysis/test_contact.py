"""Pen contact and ink strokes from a logged trace, against hand-worked traces."""

import numpy as np
import pytest

from hemg_drake.analysis.contact import CONTACT_THRESHOLD, in_contact, ink_strokes
from tooling.traces import pen_trace


def test_strokes_are_the_runs_of_contact():
    times, p_WP, touching = pen_trace("0011100101100011")
    strokes = ink_strokes(times, p_WP, touching)
    # The lone touching sample at index 7 leaves no line.
    assert [len(s) for s in strokes] == [3, 2, 2]
    np.testing.assert_array_equal(strokes[0], p_WP[2:5])
    np.testing.assert_array_equal(strokes[1], p_WP[9:11])
    np.testing.assert_array_equal(strokes[2], p_WP[14:16])
    assert len(ink_strokes(times, p_WP, touching, min_points=1)) == 4
    assert ink_strokes(times, p_WP, np.zeros(len(times), bool)) == []


@pytest.mark.parametrize("min_points", [0, -2])
def test_bad_min_points_is_refused(min_points):
    with pytest.raises(ValueError, match="min_points must be >= 1"):
        ink_strokes(*pen_trace("0110"), min_points=min_points)


def test_in_contact_thresholds_the_force_norm():
    f = np.array([[0, 0, 0], [0, 0, CONTACT_THRESHOLD * 1.01], [0.03, 0.03, 0.03], [0, 0, 0.04]])
    np.testing.assert_array_equal(in_contact(f), [False, True, True, False])
    np.testing.assert_array_equal(in_contact(f, threshold=0.0), [False, True, True, True])


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(p_WP=np.zeros((5, 3))), r"p_WP must have shape \(6, 3\)"),
        (dict(in_contact=np.ones(6)), "in_contact must be 6 booleans"),
        (dict(times=np.array([0, 0.1, 0.1, 0.2, 0.3, 0.4])), "strictly increasing"),
        (dict(p_WP=np.full((6, 3), np.nan)), "finite"),
        (dict(times=np.zeros((6, 1))), r"times must have shape \(n,\)"),
    ],
)
def test_bad_traces_are_refused(change, message):
    times, p_WP, touching = pen_trace("011110")
    arguments = dict(times=times, p_WP=p_WP, in_contact=touching) | change
    with pytest.raises(ValueError, match=message):
        ink_strokes(**arguments)


def test_bad_forces_are_refused():
    with pytest.raises(ValueError, match=r"f_WP must have shape \(n, 3\)"):
        in_contact(np.zeros(3))
    with pytest.raises(ValueError, match="NaN"):
        in_contact(np.array([[0.0, np.nan, 1.0]]))
    with pytest.raises(ValueError, match="threshold"):
        in_contact(np.zeros((2, 3)), threshold=-1.0)
