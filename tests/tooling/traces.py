"""A pen-tip trace for the contact and ink tests."""

import numpy as np


def pen_trace(pattern):
    """Times 0, 0.01, ...; tip points (t, 2t, 0); contact from a string of 0/1."""
    touching = np.array([c == "1" for c in pattern])
    times = 0.01 * np.arange(len(pattern))
    return times, np.column_stack([times, 2 * times, np.zeros_like(times)]), touching
