"""Ink: stroke extraction in numpy, and the ink's keyframes in a real Meshcat recording."""

import base64
import re

import msgpack
import numpy as np
import pytest
from pydrake.geometry import Meshcat, MeshcatParams

from hemg_drake.analysis.contact import CONTACT_THRESHOLD, in_contact, ink_strokes
from hemg_drake.viz.ink import add_ink_to_recording

FPS = 64.0


def _trace(pattern):
    """Times 0, 0.01, ...; tip points (t, 2t, 0); contact from a string of 0/1."""
    touching = np.array([c == "1" for c in pattern])
    times = 0.01 * np.arange(len(pattern))
    return times, np.column_stack([times, 2 * times, np.zeros_like(times)]), touching


def test_strokes_are_the_runs_of_contact():
    times, p_WP, touching = _trace("0011100101100011")
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
        ink_strokes(*_trace("0110"), min_points=min_points)


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
    times, p_WP, touching = _trace("011110")
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


def _animation_tracks(meshcat):
    """{path: [(frame, visible), ...]} from the recorded set_animation command of the HTML."""
    html = meshcat.StaticHtml()
    for data in re.findall(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)", html):
        command = msgpack.unpackb(base64.b64decode(data), raw=False, strict_map_key=False)
        if command.get("type") == "set_animation":
            return {
                clip["path"]: [
                    (key["time"], key["value"])
                    for track in clip["clip"]["tracks"]
                    if track["name"] == ".visible"
                    for key in track["keys"]
                ]
                for clip in command["animations"]
            }
    raise AssertionError("no animation in the recording")


@pytest.fixture
def meshcat():
    return Meshcat(MeshcatParams(host="localhost", port=0))


def test_ink_appears_piece_by_piece_in_the_recording(meshcat):
    # A long stroke (1000 samples) and a short one (30), at 100 Hz.
    pattern = "0" * 20 + "1" * 1000 + "0" * 50 + "1" * 30 + "0" * 20
    times, p_WP, touching = _trace(pattern)
    meshcat.StartRecording(frames_per_second=FPS)
    pieces = add_ink_to_recording(meshcat, times, p_WP, touching, height=0.09, max_pieces=60)
    meshcat.StopRecording()
    meshcat.PublishRecording()

    paths = [path for path, _ in pieces]
    assert all(meshcat.HasPath(path) for path in paths)
    long_pieces = [p for p in paths if p.startswith("/ink/stroke_0/")]
    short_pieces = [p for p in paths if p.startswith("/ink/stroke_1/")]
    # Shared in proportion to the samples: about 58 and 1 of the 60.
    assert 50 <= len(long_pieces) <= 60 and 1 <= len(short_pieces) <= 3
    assert len(paths) <= 62
    # The last piece of each stroke appears with the stroke's last touching sample.
    appear = dict(pieces)
    assert appear[long_pieces[-1]] == pytest.approx(times[20 + 999])
    assert appear[short_pieces[-1]] == pytest.approx(times[1070 + 29])
    assert np.all(np.diff([appear[p] for p in long_pieces]) > 0)

    tracks = _animation_tracks(meshcat)
    for path, t in pieces:
        keys = sorted(tracks[path])
        # Hidden at frame 0, visible from the frame of its time on.
        assert keys[0] == (0, False)
        frame, visible = keys[-1]
        assert visible is True and abs(frame - t * FPS) < 1.0


def test_ink_needs_enough_pieces(meshcat):
    times, p_WP, touching = _trace("0110110110")
    with pytest.raises(ValueError, match="max_pieces"):
        add_ink_to_recording(meshcat, times, p_WP, touching, max_pieces=2)
    with pytest.raises(ValueError, match="height"):
        add_ink_to_recording(meshcat, times, p_WP, touching, height=np.nan)
