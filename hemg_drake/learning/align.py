"""Aligning natural demonstrations before the HSMM learns them (``learning.align``).

A person's takes start at different times and end with the hand at rest for a while; the
HSMM's first and last states then learn the idle, with durations that vary as much as the
idle does. ``"trim"`` cuts each demonstration to its active span: from ``margin`` samples
before the first sample that moves or stiffens, to ``margin`` after the last, where moving
is a speed above ``speed_fraction`` of the take's peak speed and stiffening a gain more than
``gain_fraction`` of its range away from its level at that end of the take.
"""

import numpy as np

from hemg_drake.learning.config import ALIGNMENTS
from hemg_drake.learning.sequences import position_count
# Defaults of active_span: 5 % of the peak speed or of the gain's range, 0.2 s of 0.01 s.
SPEED_FRACTION = 0.05
GAIN_FRACTION = 0.05
MARGIN = 20


def active_span(demo, *, speed_fraction=SPEED_FRACTION, gain_fraction=GAIN_FRACTION,
                margin=MARGIN, n_position=None):  # fmt: skip
    """The active samples of one demonstration [x, xdot, k]: (begin, end), a slice's bounds.

    Parameters
    ----------
    demo : array, shape (T, D), layout [x (P), xdot (P), k (rest)].
    speed_fraction, gain_fraction : float in [0, 1)
    margin : int, samples kept on either side of the active ones.

    Returns
    -------
    (int, int): 0 <= begin < end <= T; the whole take when nothing moves nor stiffens.
    """
    demo = np.asarray(demo, dtype=float)
    count = len(demo)
    p = position_count(demo.shape[1], n_position)
    speed = np.linalg.norm(demo[:, p : 2 * p], axis=1)
    gain = demo[:, 2 * p :]
    spread = np.ptp(gain, axis=0)
    moving = speed > speed_fraction * speed.max() if speed.max() > 0 else np.zeros(count, bool)
    lead = np.any(np.abs(gain - gain[0]) > gain_fraction * spread, axis=1) if gain.size else moving
    tail = np.any(np.abs(gain - gain[-1]) > gain_fraction * spread, axis=1) if gain.size else moving
    first = np.flatnonzero(moving | lead)
    last = np.flatnonzero(moving | tail)
    if first.size == 0 or last.size == 0:
        return 0, count
    begin = max(int(first[0]) - margin, 0)
    end = min(int(last[-1]) + 1 + margin, count)
    return (begin, end) if end > begin else (0, count)


def aligned(demos, align, **options):
    """``demos`` as ``learning.align`` says: unchanged ("none") or each cut to its
    :func:`active_span` ("trim"). Returns (demos, spans), spans the (begin, end) of each."""
    if align not in ALIGNMENTS:
        raise ValueError(f"align must be one of {ALIGNMENTS}, got {align!r}")
    if align == "none":
        return list(demos), [(0, len(d)) for d in demos]
    spans = [active_span(d, **options) for d in demos]
    return [d[b:e] for d, (b, e) in zip(demos, spans, strict=True)], spans
