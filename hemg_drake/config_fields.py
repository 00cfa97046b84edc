"""The one field helper of every ``...Config`` dataclass: a default and its range checks.

A config module (``hemg_drake/<package>/config.py``) imports only the standard library, numpy
and this module, so loading a scenario imports no system. :func:`check_config` checks a
loaded config (``hemg_drake.scenario.load_scenario`` calls it on the whole scenario): each
field against its metadata, then each config's own ``check(key)`` method, if it has one, for
the rules between its fields; every error names the key of the value at fault.
"""

import dataclasses as dc

import numpy as np

# The checks a field may carry (numbers must be >= 0 unless ``signed``).
CHECKS = ("positive", "signed", "fraction", "maximum", "why", "size", "choices")


def checked(default, **checks):
    """A dataclass field with its default and its range checks.

    Parameters
    ----------
    default : the value; a list, tuple or array is copied per instance.
    **checks : ``positive`` (> 0), ``signed`` (negative allowed), ``fraction`` (in [0, 1]),
        ``maximum``, ``why`` (what the maximum stands for, said in its message: "10 s of 1 ms
        samples"), ``size`` (a vector's length, or a tuple of allowed lengths), ``choices``
        (the allowed values).
    """
    unknown = set(checks) - set(CHECKS)
    if unknown:
        raise TypeError(f"unknown checks {sorted(unknown)}; allowed: {CHECKS}")
    if isinstance(default, (list, tuple)) or hasattr(default, "tolist"):
        items = list(default.tolist() if hasattr(default, "tolist") else default)
        return dc.field(default_factory=lambda: list(items), metadata=checks)
    return dc.field(default=default, metadata=checks)


def key_path(key, name):
    """The key path of field ``name`` in the config at ``key``: ``"emg.k_max"``, ``"k_max"``."""
    return f"{key}.{name}" if key else name


def check_config(config, key=""):
    """Check a loaded config against its fields' metadata, then its own ``check(key)``.

    Walks the nested configs (dataclasses, and Drake's config structs, whose fields carry no
    metadata: their numbers must be finite and >= 0). A number must be finite, and >= 0
    unless its field is ``signed``; lists are checked element by element. A config with a
    ``check(key)`` method is then asked for the checks its fields cannot express alone (one
    field against another), after its fields: it raises ValueError naming keys under
    ``key``.

    Parameters
    ----------
    config : a dataclass (or Drake config struct) instance.
    key : str, the config's key path in its file ("" for the top level).

    Raises
    ------
    ValueError
        ``key '<path>' ...``: the key path of the first value out of range, in one line.
    """
    for name, checks in _fields(config):
        path = key_path(key, name)
        value = getattr(config, name)
        if _is_config(value):
            check_config(value, path)
        else:
            _check_value(path, value, checks)
    check = getattr(config, "check", None)
    if callable(check):
        check(key)


def _is_config(value):
    return (dc.is_dataclass(value) and not isinstance(value, type)) or hasattr(
        type(value), "__fields__"
    )


def _fields(config):
    """(name, checks) of a config's fields; Drake's config structs list theirs in __fields__."""
    if dc.is_dataclass(config):
        return [(f.name, f.metadata) for f in dc.fields(config)]
    return [(f.name, {}) for f in type(config).__fields__]


def _check_value(key, value, checks):
    choices = checks.get("choices")
    if choices is not None and value not in choices:
        raise ValueError(f"key '{key}' = {value!r} is not one of {tuple(choices)}")
    if value is None or isinstance(value, (bool, str)):
        return
    try:
        numbers = np.array(value, dtype=float)
    except (TypeError, ValueError):  # strings (plan.kinds), ragged lists: their config checks
        return
    size = checks.get("size")
    sizes = size if isinstance(size, tuple) else (size,)
    if size is not None and not (numbers.ndim == 1 and len(numbers) in sizes):
        count = " or ".join(str(n) for n in sizes)
        raise ValueError(f"key '{key}' must hold {count} numbers, got {value!r}")
    if not np.all(np.isfinite(numbers)):
        raise ValueError(f"key '{key}' must be finite, got {value!r}")
    if checks.get("positive") and np.any(numbers <= 0):
        raise ValueError(f"key '{key}' must be positive, got {value!r}")
    if not checks.get("signed") and np.any(numbers < 0):
        raise ValueError(f"key '{key}' must not be negative, got {value!r}")
    maximum = checks.get("maximum")
    if maximum is not None and np.any(numbers > maximum):
        why = f" ({checks['why']})" if checks.get("why") else ""
        raise ValueError(f"key '{key}' must be at most {maximum:g}{why}, got {value!r}")
    if checks.get("fraction") and np.any(numbers > 1):
        raise ValueError(f"key '{key}' must lie in [0, 1], got {value!r}")
