"""The one field helper of every ``...Config`` dataclass: a default and its range checks.

A config module (``hemg_drake/<package>/config.py``) imports only the standard library, numpy
and this module, so loading a scenario imports no system. The checks are read by
:func:`hemg_drake.scenario.load_scenario`, which names the key of the first value out of range.
"""

import dataclasses as dc

# The checks a field may carry (numbers must be >= 0 unless ``signed``).
CHECKS = ("positive", "signed", "fraction", "maximum", "size", "choices")


def checked(default, **checks):
    """A dataclass field with its default and its range checks.

    Parameters
    ----------
    default : the value; a list, tuple or array is copied per instance.
    **checks : ``positive`` (> 0), ``signed`` (negative allowed), ``fraction`` (in [0, 1]),
        ``maximum``, ``size`` (a vector's length, or a tuple of allowed lengths), ``choices``
        (the allowed values).
    """
    unknown = set(checks) - set(CHECKS)
    if unknown:
        raise TypeError(f"unknown checks {sorted(unknown)}; allowed: {CHECKS}")
    if isinstance(default, (list, tuple)) or hasattr(default, "tolist"):
        items = list(default.tolist() if hasattr(default, "tolist") else default)
        return dc.field(default_factory=lambda: list(items), metadata=checks)
    return dc.field(default=default, metadata=checks)
