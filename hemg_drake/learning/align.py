"""Aligning natural demonstrations before the HSMM learns them (``learning.align``).

A person's takes start at different times and end with the hand at rest for a while; the
HSMM's first and last states then learn the idle, with durations that vary as much as the
idle does. ``"trim"`` cuts each demonstration to its active span: from ``margin`` samples
before the first sample that has moved or stiffened, to ``margin`` after the last, where
moved is a position more than ``distance`` from the take's first (for the lead-in) or last
(lead-out) one, and stiffened a gain above its rest level (10th percentile) by more than
``gain_fraction`` of its range. Positions and a threshold on the gain's level, not speeds
nor gain changes: the arm's settling at the start of a take and the sEMG's noise at rest
(measured: up to 0.02 m/s and 25 % of the range) would pass for motion.

``"dtw"`` time-warps every demonstration onto a reference one (the take of median length)
by dynamic time warping on the positions (learning/dtw.py): each sample of the reference
gets the mean of the demonstration's samples matched to it (positions, velocities, gain).
The takes then share the reference's timing and length, so a state of the HSMM's
initialisation covers the same part of the path in every take; a person's pauses and
changes of tempo no longer split it differently from take to take.
"""

import numpy as np

from hemg_drake.learning.config import ALIGNMENTS
from hemg_drake.learning.dtw import dtw_path
from hemg_drake.learning.sequences import position_count

# Defaults of active_span: 5 mm, 30 % of the gain's range, 0.2 s of 0.01 s samples.
DISTANCE = 0.005
GAIN_FRACTION = 0.3
REST_PERCENTILE = 10.0
MARGIN = 20


def active_span(demo, *, distance=DISTANCE, gain_fraction=GAIN_FRACTION, margin=MARGIN,
                n_position=None):  # fmt: skip
    """The active samples of one demonstration [x, xdot, k]: (begin, end), a slice's bounds.

    Parameters
    ----------
    demo : array, shape (T, D), layout [x (P), xdot (P), k (rest)].
    distance : float, m; gain_fraction : float in [0, 1); margin : int, samples kept on
        either side of the active ones.

    Returns
    -------
    (int, int): 0 <= begin < end <= T; the whole take when nothing moves nor stiffens.
    """
    demo = np.asarray(demo, dtype=float)
    count = len(demo)
    p = position_count(demo.shape[1], n_position)
    x, gain = demo[:, :p], demo[:, 2 * p :]
    stiff = np.zeros(count, bool)
    if gain.size:
        rest = np.percentile(gain, REST_PERCENTILE, axis=0)
        stiff = np.any(gain - rest > gain_fraction * np.ptp(gain, axis=0), axis=1)
    first = np.flatnonzero(stiff | (np.linalg.norm(x - x[0], axis=1) > distance))
    last = np.flatnonzero(stiff | (np.linalg.norm(x - x[-1], axis=1) > distance))
    if first.size == 0 or last.size == 0:
        return 0, count
    begin = max(int(first[0]) - margin, 0)
    end = min(int(last[-1]) + 1 + margin, count)
    return (begin, end) if end > begin else (0, count)


def warped_onto(demo, reference, n_position=None):
    """``demo`` time-warped onto ``reference``'s samples by DTW on the positions.

    Parameters
    ----------
    demo : array, shape (T, D); reference : array, shape (T_ref, D), layout [x (P), ...].

    Returns
    -------
    array, shape (T_ref, D): row i the mean of ``demo``'s rows that the warping path
    matches to reference row i (every one is matched at least once).
    """
    demo, reference = np.asarray(demo, float), np.asarray(reference, float)
    p = position_count(demo.shape[1], n_position)
    index_ref, index_demo = dtw_path(reference[:, :p], demo[:, :p])
    total = np.zeros((len(reference), demo.shape[1]))
    np.add.at(total, index_ref, demo[index_demo])
    return total / np.bincount(index_ref, minlength=len(reference))[:, None]


def reference_take(demos):
    """Index of the take of median length (the first such): the timing the others take on."""
    lengths = [len(d) for d in demos]
    return int(np.argsort(lengths, kind="stable")[(len(lengths) - 1) // 2])


def aligned(demos, align, **options):
    """``demos`` as ``learning.align`` says: unchanged ("none"), each cut to its
    :func:`active_span` ("trim"), or each warped onto the :func:`reference_take` ("dtw").
    Returns (demos, spans), spans the (begin, end) of each sample range kept."""
    if align not in ALIGNMENTS:
        raise ValueError(f"align must be one of {ALIGNMENTS}, got {align!r}")
    if align == "none":
        return list(demos), [(0, len(d)) for d in demos]
    if align == "dtw":
        reference = demos[reference_take(demos)]
        return [warped_onto(d, reference, options.get("n_position")) for d in demos], [
            (0, len(d)) for d in demos]  # fmt: skip
    spans = [active_span(d, **options) for d in demos]
    return [d[b:e] for d, (b, e) in zip(demos, spans, strict=True)], spans
