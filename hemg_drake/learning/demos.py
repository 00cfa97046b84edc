"""Demonstrations as data: the logged record, one-file NPZ datasets, observations for learning.

A dataset is one NPZ file holding C demonstrations and a metadata record::

    save_dataset("runs/pin/dataset.npz", demos, {"scenario": scenario.to_yaml(), ...})
    demos, metadata = load_dataset("runs/pin/dataset.npz")
    X = observations(demos)            # list of C arrays (T_c, 7): x, xdot, k

Layout: arrays ``demo<c>.<field>`` for every field of :class:`Demonstration` (c = 0 ..
C - 1), and ``metadata``, a JSON string with ``format_version``, ``num_demonstrations``,
``seeds``, ``versions`` (hemg_drake, drake, numpy) and whatever the caller adds (the
scenario's YAML text). Only plain arrays are stored (no pickles).
"""

import dataclasses as dc
import json
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

import hemg_drake
from hemg_drake.fileio import load_npz, save_npz_atomic

FORMAT_VERSION = 1
# Number of columns of each logged field (1 for a scalar signal, stored as shape (T,)).
FIELD_WIDTHS = {
    "time": 1,
    "p_WE": 3,
    "v_WE": 3,
    "p_MS": 3,
    "envelope": 1,
    "activation": 1,
    "gain": 1,
    "f_WE": 3,
}


@dc.dataclass(frozen=True, eq=False)
class Demonstration:
    """One demonstration as logged every ``log_period`` (Table I: 0.01 s); T samples.

    Attributes
    ----------
    seed : int
        The seed the demonstration was run with.
    time : array, shape (T,)
        Sample times (s), increasing.
    p_WE, v_WE : array, shape (T, 3)
        Slave tool point E in the world: position (m) and velocity (m/s).
    p_MS : array, shape (T, 3)
        Master stylus tip S in the master frame M (m).
    envelope : array, shape (T,)
        Raw RMS envelope of the summed sEMG (MYO units, eqs. 1-2).
    activation : array, shape (T,)
        Muscle activation a(u) in [0, 1] (eq. 22).
    gain : array, shape (T,)
        Slave gain K, the stiffness the robot learns (eq. 22).
    f_WE : array, shape (T, 3)
        Force of the environment on the slave's tool point, in the world (N).
    """

    seed: int
    time: np.ndarray
    p_WE: np.ndarray
    v_WE: np.ndarray
    p_MS: np.ndarray
    envelope: np.ndarray
    activation: np.ndarray
    gain: np.ndarray
    f_WE: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "seed", int(self.seed))
        length = None
        for name, width in FIELD_WIDTHS.items():
            array = np.asarray(getattr(self, name), dtype=float)
            length = len(array) if length is None else length
            shape = (length,) if width == 1 else (length, width)
            if array.shape != shape:
                raise ValueError(
                    f"Demonstration field '{name}' must have shape {shape}, got {array.shape}"
                )
            if not np.all(np.isfinite(array)):
                raise ValueError(f"Demonstration field '{name}' contains NaN or inf")
            object.__setattr__(self, name, array)

    def __len__(self):
        return len(self.time)


def versions():
    """Versions of hemg_drake, drake and numpy, for a dataset's metadata."""
    try:
        drake = version("drake")
    except PackageNotFoundError:  # a source build of Drake
        drake = "unknown"
    return {"hemg_drake": hemg_drake.__version__, "drake": drake, "numpy": np.__version__}


def save_dataset(path, demos, metadata=None):
    """Write C demonstrations and their metadata to one NPZ file, atomically.

    Parameters
    ----------
    path : path-like
        The file to write (no suffix is added); replaced atomically if it exists.
    demos : sequence of Demonstration, C >= 1.
    metadata : dict, optional
        JSON-serialisable extras, e.g. ``{"scenario": yaml_text}``; ``format_version``,
        ``num_demonstrations``, ``seeds`` and ``versions`` are filled in.
    """
    demos = list(demos)
    if not demos or not all(isinstance(d, Demonstration) for d in demos):
        raise ValueError("save_dataset needs a non-empty list of Demonstration")
    record = dict(metadata or {})
    record.update(
        format_version=FORMAT_VERSION,
        num_demonstrations=len(demos),
        seeds=[d.seed for d in demos],
        versions=versions(),
    )
    try:
        text = json.dumps(record, sort_keys=True)
    except TypeError as error:
        raise ValueError(f"dataset metadata must be JSON-serialisable: {error}") from None
    arrays = {"metadata": np.array(text)}
    for c, demo in enumerate(demos):
        for name in FIELD_WIDTHS:
            arrays[f"demo{c}.{name}"] = getattr(demo, name)
    save_npz_atomic(path, **arrays)


def load_dataset(path):
    """Read a dataset written by :func:`save_dataset`.

    Returns
    -------
    demos : list of Demonstration
    metadata : dict

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Not a readable NPZ, no or unreadable metadata, another format version, a missing
        or malformed array: the message names the file and the array.
    """
    path = Path(path)
    arrays = load_npz(path, kind="dataset")
    if "metadata" not in arrays:
        raise ValueError(f"{path}: no 'metadata' array; not a hemg_drake dataset")
    try:
        metadata = json.loads(str(arrays["metadata"]))
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: metadata is not valid JSON: {error}") from None
    if not isinstance(metadata, dict) or metadata.get("format_version") != FORMAT_VERSION:
        found = metadata.get("format_version") if isinstance(metadata, dict) else None
        raise ValueError(
            f"{path}: dataset format version {found!r}, this hemg_drake reads {FORMAT_VERSION}"
        )
    count, seeds = metadata.get("num_demonstrations"), metadata.get("seeds")
    valid = isinstance(count, int) and count >= 1 and isinstance(seeds, list)
    if not valid or len(seeds) != count:
        raise ValueError(f"{path}: metadata needs num_demonstrations >= 1 and one seed each")
    demos = []
    for c in range(count):
        fields = {}
        for name in FIELD_WIDTHS:
            key = f"demo{c}.{name}"
            if key not in arrays:
                raise ValueError(f"{path}: missing array '{key}'")
            fields[name] = arrays[key]
        try:
            demos.append(Demonstration(seed=seeds[c], **fields))
        except (TypeError, ValueError) as error:
            raise ValueError(f"{path}: demonstration {c}: {error}") from None
    return demos, metadata


def observations(demos, fields=("p_WE", "v_WE", "gain")):
    """Stack logged fields column-wise into the learning core's observations.

    Parameters
    ----------
    demos : sequence of Demonstration
    fields : sequence of str
        Names of :class:`Demonstration` fields, in column order. The default gives the
        paper's xi = [x, xdot, k], D = 3 + 3 + 1 = 7.

    Returns
    -------
    list of array, shape (T_c, D), one per demonstration.
    """
    unknown = [name for name in fields if name not in FIELD_WIDTHS or name == "time"]
    if unknown or not fields:
        raise ValueError(
            f"observations: fields must be names among {sorted(set(FIELD_WIDTHS) - {'time'})}, "
            f"got {list(fields)}"
        )
    return [
        np.column_stack([getattr(demo, name) for name in fields]) for demo in demos
    ]
