"""Ink: the ink's keyframes in a real Meshcat recording (its strokes: tests/analysis)."""

import base64
import re

import msgpack
import numpy as np
import pytest
from pydrake.geometry import Meshcat, MeshcatParams

from hemg_drake.viz.ink import add_ink_to_recording
from tooling.traces import pen_trace

FPS = 64.0


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
    times, p_WP, touching = pen_trace(pattern)
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
    times, p_WP, touching = pen_trace("0110110110")
    with pytest.raises(ValueError, match="max_pieces"):
        add_ink_to_recording(meshcat, times, p_WP, touching, max_pieces=2)
    with pytest.raises(ValueError, match="height"):
        add_ink_to_recording(meshcat, times, p_WP, touching, height=np.nan)
