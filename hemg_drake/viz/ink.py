"""Ink: where the pen touched the paper, as traces in a Meshcat replay.

The trace comes from a log of the pen tip P and its contact force, sampled together (the
demonstration's logger records ``p_WE`` and ``f_WE`` every 0.01 s; in the drawing scene the
tool point E is the pen's tip)::

    touching = in_contact(f_WP)                           # |f| above a threshold
    strokes = ink_strokes(times, p_WP, touching)          # list of (k, 3) polylines
    add_ink_to_recording(recorder.meshcat, times, p_WP, touching, height=paper_z + 5e-4)

:func:`add_ink_to_recording` must run while the visualizer's recording is still open (after
the simulation, before ``ReplayRecorder.stop_and_export``; ``export_station_replay`` does
it for a drawing): Meshcat cannot record
``SetObject`` mid-animation (Drake issue 23206), so every piece of ink is created at once,
hidden at time 0 and made visible at the time it was drawn.
"""

import numpy as np
from pydrake.geometry import Rgba

from hemg_drake.analysis.contact import (
    CONTACT_THRESHOLD,
    checked_trace,
    contact_runs,
    in_contact,
    ink_strokes,
)

# The ink's detection is analysis (hemg_drake.analysis.contact), re-exported here.
__all__ = [
    "CONTACT_THRESHOLD", "INK_PATH", "INK_RGBA", "add_ink_to_recording", "in_contact",
    "ink_strokes",
]  # fmt: skip
INK_RGBA = Rgba(0.05, 0.45, 0.15, 1.0)
# Meshcat folder of the ink.
INK_PATH = "/ink"


def add_ink_to_recording(
    meshcat,
    times,
    p_WP,
    in_contact,
    *,
    path=INK_PATH,
    height=None,
    max_pieces=100,
    line_width=3.0,
    rgba=INK_RGBA,
):
    """Draw the ink into ``meshcat``'s open recording so that it appears as it was drawn.

    Each stroke is cut into pieces of consecutive line segments; all pieces get about
    ``max_pieces`` in total, shared in proportion to the strokes' sample counts, at least one
    per stroke (Meshcat slows down with thousands of animated objects). Every piece is
    created now with ``SetLineSegments`` at ``{path}/stroke_{i}/piece_{j}``, hidden at
    recording time 0, and made visible at the time of its last sample.

    Parameters
    ----------
    meshcat : Meshcat, recording (``MeshcatVisualizer.StartRecording`` called, not stopped).
    times, p_WP, in_contact : as for :func:`ink_strokes`.
    path : str, Meshcat folder of the ink (deleted first).
    height : float, optional; draw the ink at this z (m), e.g. just above the paper, instead
        of the recorded tip heights (which are slightly inside the compliant paper).
    max_pieces : int, >= number of strokes.
    line_width : float, pixels (WebGL may draw 1).
    rgba : Rgba.

    Returns
    -------
    list of (str, float): each piece's Meshcat path and the time it appears.
    """
    times, p_WP, touching = checked_trace(times, p_WP, in_contact)
    if height is not None:
        if not np.isfinite(height):
            raise ValueError(f"height must be finite, got {height}")
        p_WP = p_WP.copy()
        p_WP[:, 2] = height
    runs = contact_runs(touching, 2)
    if int(max_pieces) < max(len(runs), 1):
        raise ValueError(f"max_pieces must be at least the number of strokes ({len(runs)})")
    total_segments = sum(b - a - 1 for a, b in runs)
    meshcat.Delete(path)
    pieces = []
    for i, (a, b) in enumerate(runs):
        count = max(1, int(max_pieces * (b - a - 1) / total_segments))
        # Piece boundaries share their end sample, so the line stays unbroken.
        bounds = np.unique(np.linspace(a, b - 1, count + 1).round().astype(int))
        for j, (first, last) in enumerate(zip(bounds[:-1], bounds[1:])):
            piece = f"{path}/stroke_{i}/piece_{j}"
            meshcat.SetLineSegments(
                piece,
                np.asfortranarray(p_WP[first:last].T),
                np.asfortranarray(p_WP[first + 1 : last + 1].T),
                line_width,
                rgba,
            )
            meshcat.SetProperty(piece, "visible", False, time_in_recording=0.0)
            meshcat.SetProperty(piece, "visible", True, time_in_recording=float(times[last]))
            pieces.append((piece, float(times[last])))
    return pieces
