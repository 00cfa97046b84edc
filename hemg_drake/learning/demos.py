"""Demonstrations as data: the logged record, one-file NPZ datasets, observations for learning.

A dataset is one NPZ file holding C demonstrations and a metadata record::

    save_dataset("runs/pin/dataset.npz", demos, {"scenario": scenario.to_yaml(), ...})
    demos, metadata = load_dataset("runs/pin/dataset.npz")
    X = observations(demos)            # list of C arrays (T_c, 7): x, xdot, k

Layout: arrays ``demo<c>.<field>`` for every field of :class:`Demonstration` (c = 0 ..
C - 1), and ``metadata``, a JSON string with ``format_version``, ``num_demonstrations``,
``seeds``, ``versions`` (hemg_drake, drake, numpy) and whatever the caller adds (the
scenario's YAML text). Only plain arrays are stored (no pickles).

Format 2 (this version) adds what later stages read instead of rebuilding it: the reference
the CLIK received (``p_WE_desired``), and at the MYO's 200 Hz the raw sEMG the gain chain
read (``emg``) with the operator's muscle activation that drove it. Format 3 (this
version) adds each demonstration's task frames, ``demo<c>.frame_A`` (F, 3, 3) and
``demo<c>.frame_b`` (F, 3): the robot's base and the scene frame T where it was shown
(``hemg_drake.placements.task_frames``), for demonstrations at many placements. Format 2
datasets load without frames (``frame_A`` None: one placement, the scenario's); format 1
datasets are refused with a message to record them again.

Format 3 datasets recorded since the arm's joints are logged also hold, at the log period,
``demo<c>.q`` (T, 7), the arm's joint positions, and ``demo<c>.R_WE`` (T, 3, 3), the tool
frame's rotation in W; older ones load with both None (the format number stays 3: an older
hemg_drake reads the new files, ignoring the two arrays). The orientation is kept as the
rotation matrix Drake computes, unique and continuous; a quaternion (:func:`tool_quaternions`)
has two signs per rotation, a convention each consumer fixes its own way.
"""

import dataclasses as dc
import json
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

import hemg_drake
from hemg_drake.fileio import load_npz, save_npz_atomic

FORMAT_VERSION = 3
# Formats this version reads (2: no task frames).
READABLE_FORMATS = (2, 3)
# Number of columns of each field logged every log period (1: a scalar signal, shape (T,)).
FIELD_WIDTHS = {
    "time": 1,
    "p_WE": 3,
    "v_WE": 3,
    "p_MS": 3,
    "p_WE_desired": 3,
    "envelope": 1,
    "activation": 1,
    "gain": 1,
    "f_WE": 3,
}
# Fields logged at the MYO's rate (200 Hz), on their own time base ``emg_time``.
EMG_FIELD_WIDTHS = {"emg_time": 1, "emg": 8, "muscle_activation": 1}
ALL_FIELDS = (*FIELD_WIDTHS, *EMG_FIELD_WIDTHS)
# The arm's joint positions and the tool's orientation at the log period, name -> the shape
# of one sample; both or neither (None: a dataset recorded before they were logged).
ARM_FIELD_SHAPES = {"q": (7,), "R_WE": (3, 3)}


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
    p_WE_desired : array, shape (T, 3)
        The reference the CLIK received (m, W): the master mapped to the slave, after the
        channel's transport delay.
    envelope : array, shape (T,)
        Raw RMS envelope of the summed sEMG (MYO units, eqs. 1-2).
    activation : array, shape (T,)
        Muscle activation a(u) in [0, 1] (eq. 22).
    gain : array, shape (T,)
        Slave gain K, the stiffness the robot learns (eq. 22).
    f_WE : array, shape (T, 3)
        Force of the environment on the slave's tool point, in the world (N).
    emg_time : array, shape (T_e,)
        Times of the 200 Hz sEMG samples (s): sample k at k / 200 s.
    emg : array, shape (T_e, 8)
        The raw sEMG samples the gain chain read (MYO units, int8 values).
    muscle_activation : array, shape (T_e,)
        The operator's muscle activation in [0, 1] that drove each sEMG sample.
    frame_A, frame_b : arrays, shape (F, 3, 3) and (F, 3), or None
        The task frames where it was shown (rotations and origins in W: the robot's base,
        the scene frame T); None for a record without them (one placement).
    q : array, shape (T, 7), or None
        The arm's joint positions (rad), in ``JOINT_NAMES`` order (right_s0 ... right_w2).
    R_WE : array, shape (T, 3, 3), or None
        The tool frame E's rotation in the world (the frame whose origin is p_WE); with
        ``q``, None for a record made before they were logged.
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
    p_WE_desired: np.ndarray
    emg_time: np.ndarray
    emg: np.ndarray
    muscle_activation: np.ndarray
    frame_A: np.ndarray = None
    frame_b: np.ndarray = None
    q: np.ndarray = None
    R_WE: np.ndarray = None

    def __post_init__(self):
        object.__setattr__(self, "seed", int(self.seed))
        self._check_frames()
        self._check_arm()
        for widths in (FIELD_WIDTHS, EMG_FIELD_WIDTHS):
            length = None
            for name, width in widths.items():
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

    def _check_frames(self):
        if self.frame_A is None and self.frame_b is None:
            return
        if self.frame_A is None or self.frame_b is None:
            raise ValueError("Demonstration fields 'frame_A' and 'frame_b' go together")
        A = np.asarray(self.frame_A, dtype=float)
        b = np.asarray(self.frame_b, dtype=float)
        if A.ndim != 3 or A.shape[1:] != (3, 3) or b.shape != (len(A), 3) or len(A) < 1:
            raise ValueError(
                f"Demonstration fields 'frame_A', 'frame_b' must have shapes (F, 3, 3), (F, 3), "
                f"got {A.shape}, {b.shape}"
            )
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(b))):
            raise ValueError("Demonstration fields 'frame_A', 'frame_b' contain NaN or inf")
        object.__setattr__(self, "frame_A", A)
        object.__setattr__(self, "frame_b", b)

    def _check_arm(self):
        if self.q is None and self.R_WE is None:
            return
        if self.q is None or self.R_WE is None:
            raise ValueError("Demonstration fields 'q' and 'R_WE' go together")
        for name, shape in ARM_FIELD_SHAPES.items():
            array = np.asarray(getattr(self, name), dtype=float)
            if array.shape != (len(self.time), *shape):
                raise ValueError(
                    f"Demonstration field '{name}' must have shape {(len(self.time), *shape)}, "
                    f"got {array.shape}"
                )
            if not np.all(np.isfinite(array)):
                raise ValueError(f"Demonstration field '{name}' contains NaN or inf")
            object.__setattr__(self, name, array)
        R = self.R_WE
        error = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(initial=0.0)
        if error > 1e-6 or np.any(np.linalg.det(R) < 0):
            raise ValueError(
                f"Demonstration field 'R_WE' must hold rotation matrices (R R^T = I within 1e-6, "
                f"det +1), off by {error:.3g}"
            )

    @property
    def frames(self):
        """(frame_A, frame_b), or None."""
        return None if self.frame_A is None else (self.frame_A, self.frame_b)


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
    if len({demo.frame_A is None for demo in demos}) > 1:
        raise ValueError("save_dataset: give task frames for every demonstration or for none")
    if len({demo.q is None for demo in demos}) > 1:
        raise ValueError("save_dataset: give q and R_WE for every demonstration or for none")
    arrays = {"metadata": np.array(text)}
    for c, demo in enumerate(demos):
        for name in ALL_FIELDS:
            arrays[f"demo{c}.{name}"] = getattr(demo, name)
        optional = [*(("frame_A", "frame_b") if demo.frame_A is not None else ()),
                    *(ARM_FIELD_SHAPES if demo.q is not None else ())]  # fmt: skip
        for name in optional:
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
    if not isinstance(metadata, dict) or "format_version" not in metadata:
        raise ValueError(f"{path}: the metadata has no format_version; not a hemg_drake dataset")
    found = metadata["format_version"]
    if found not in READABLE_FORMATS:
        advice = (
            "it lacks the raw sEMG and the CLIK's reference that learning and Fig. 6 read; "
            "record it again with hemg-drake demonstrate"
            if found == 1
            else "it was written by another hemg_drake version"
        )
        raise ValueError(
            f"{path}: dataset format {found!r}, this hemg_drake reads format "
            f"{' or '.join(map(str, READABLE_FORMATS))}: {advice}"
        )
    count, seeds = metadata.get("num_demonstrations"), metadata.get("seeds")
    valid = isinstance(count, int) and count >= 1 and isinstance(seeds, list)
    if not valid or len(seeds) != count:
        raise ValueError(f"{path}: metadata needs num_demonstrations >= 1 and one seed each")
    demos = []
    for c in range(count):
        fields = {}
        for name in ALL_FIELDS:
            key = f"demo{c}.{name}"
            if key not in arrays:
                raise ValueError(f"{path}: missing array '{key}'")
            fields[name] = arrays[key]
        for name in ("frame_A", "frame_b", *ARM_FIELD_SHAPES):
            if f"demo{c}.{name}" in arrays:
                fields[name] = arrays[f"demo{c}.{name}"]
        try:
            demos.append(Demonstration(seed=seeds[c], **fields))
        except (TypeError, ValueError) as error:
            raise ValueError(f"{path}: demonstration {c + 1}: {error}") from None
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


def tool_quaternions(demos):
    """The tool's orientation in each demonstration as unit quaternions [w, x, y, z].

    Drake's ``RotationMatrix.ToQuaternion`` of ``R_WE``, with the signs made continuous:
    q and -q are one rotation, and Drake's canonical w >= 0 flips the sign wherever the
    rotation angle passes 180 deg, which is where the shipped tasks hold the tool (pointing
    down: w is 0.05 at the pin's start). Each sample takes the sign nearer the sample
    before; each demonstration's first, the sign nearer the first demonstration's first
    (which keeps w >= 0), so the whole dataset lies on one side.

    Returns
    -------
    list of array, shape (T_c, 4), one per demonstration; None if any has no ``R_WE``.
    """
    from pydrake.math import RotationMatrix

    demos = list(demos)
    if not demos or any(demo.R_WE is None for demo in demos):
        return None
    result, reference = [], None
    for demo in demos:
        quats = np.array(
            [RotationMatrix(R).ToQuaternion().wxyz() for R in demo.R_WE]
        ).reshape(-1, 4)
        if not len(quats):
            result.append(quats)
            continue
        reference = quats[0] if reference is None else reference
        steps = np.einsum("ij,ij->i", quats[1:], quats[:-1])
        first = 1.0 if quats[0] @ reference >= 0 else -1.0
        signs = first * np.cumprod(np.r_[1.0, np.where(steps < 0, -1.0, 1.0)])
        result.append(quats * signs[:, None])
    return result


def demonstrated_gain(demos, duration, samples=400):
    """The demonstrations' own gain K replayed in time (``reproduction.gain_source:
    demonstrated``): each demonstration's K at the same fractions of its length, averaged,
    on times [0, ``duration``]. Returns (times, K), arrays of shape (samples,)."""
    fractions = np.linspace(0.0, 1.0, samples)
    gains = [
        np.interp(fractions, (d.time - d.time[0]) / (d.time[-1] - d.time[0]), d.gain)
        for d in demos
    ]
    return fractions * duration, np.mean(gains, axis=0)
