"""Raw sEMG recordings: read and write them (CSV or NPZ), and replay one in a diagram.

A recording is the MYO's raw samples: 8 channels, integers in -128..127, one row per
1/200 s. ``make_file_emg_source`` replays it with Drake's own systems: a
``TrajectorySource`` of the rows held between sample instants, sampled by a
``ZeroOrderHold`` at t_k = k / 200 s (zero before the first sample).
"""

import math
from pathlib import Path

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ZeroOrderHold

from hemg_drake._validate import as_scalar
from hemg_drake.emg.config import INT8_MAX, INT8_MIN, MYO_CHANNELS, MYO_PERIOD
from hemg_drake.emg.synthetic import held_samples
from hemg_drake.fileio import load_npz, save_npz_atomic, write_text_atomic

NPZ_KEY = "emg"


def _int8_problem(value):
    if not INT8_MIN <= value <= INT8_MAX:
        return f"value {value} is outside the int8 range {INT8_MIN}..{INT8_MAX}"
    return None


def _int8_array_problem(emg):
    """What is wrong with the first value of ``emg`` (2-D) that is not an int8 integer, or None."""
    if not np.issubdtype(emg.dtype, np.number) or np.issubdtype(emg.dtype, np.complexfloating):
        return f"array {NPZ_KEY!r} has non-numeric dtype {emg.dtype}"
    checks = (
        (np.isnan(emg), "NaN"),
        (~np.isfinite(emg), "an infinite value"),
        (np.round(emg) != emg, "a non-integer value"),
        ((emg < INT8_MIN) | (emg > INT8_MAX), f"a value outside {INT8_MIN}..{INT8_MAX}"),
    )
    for bad, what in checks:
        if np.any(bad):
            row, column = np.argwhere(bad)[0]
            return f"row {row + 1}, column {column + 1}: {what} ({emg[row, column]})"
    return None


def _load_csv(path):
    rows = []
    with open(path, encoding="utf-8") as f:
        for line_number, line in enumerate(f, start=1):
            if not line.strip():
                continue
            fields = line.split(",")
            where = f"{path}: line {line_number}"
            if len(fields) != MYO_CHANNELS:
                raise ValueError(
                    f"{where}: expected {MYO_CHANNELS} comma-separated columns, found {len(fields)}"
                )
            row = []
            for column, field in enumerate(fields, start=1):
                try:
                    value = int(field.strip())
                except ValueError:
                    raise ValueError(
                        f"{where}: column {column}: {field.strip()!r} is not an integer"
                    ) from None
                problem = _int8_problem(value)
                if problem:
                    raise ValueError(f"{where}: column {column}: {problem}")
                row.append(value)
            rows.append(row)
    return np.array(rows, dtype=np.int64).reshape(-1, MYO_CHANNELS)


def _load_npz(path):
    arrays = load_npz(path, kind="sEMG recording")
    if NPZ_KEY not in arrays:
        raise ValueError(f"{path}: no array named {NPZ_KEY!r} (found {sorted(arrays)})")
    emg = arrays[NPZ_KEY]
    if emg.ndim != 2 or emg.shape[1] != MYO_CHANNELS:
        raise ValueError(
            f"{path}: array {NPZ_KEY!r} must have shape (n_samples, {MYO_CHANNELS}), "
            f"got {emg.shape}"
        )
    problem = _int8_array_problem(emg)
    if problem:
        raise ValueError(f"{path}: {problem}")
    return emg.astype(np.int64)


def load_emg_recording(path):
    """Read a raw sEMG recording: CSV (8 integer columns, no header) or NPZ.

    CSV: one 200 Hz sample per line, 8 comma-separated integers in -128..127,
    no header (the layout of public MYO data sets); blank lines are skipped.
    NPZ (``.npz`` suffix): an array named ``"emg"`` of shape (n_samples, 8)
    holding integer values in -128..127 (any numeric dtype).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    emg : ndarray of int64, shape (n_samples, 8)

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        The file is malformed; the message names the file, the line (CSV) or
        row (NPZ) and the problem.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"EMG recording not found: {path}")
    emg = _load_npz(path) if path.suffix.lower() == ".npz" else _load_csv(path)
    if len(emg) == 0:
        raise ValueError(f"{path}: the recording holds no samples")
    return emg


def save_emg_recording(path, emg):
    """Write raw sEMG atomically in the layout ``load_emg_recording`` reads.

    Parameters
    ----------
    path : str or Path
        ``.npz``: an array named ``"emg"``; any other suffix: CSV, 8 integer
        columns, no header.
    emg : array-like, shape (n_samples, 8)
        Integers in -128..127, at least one sample.
    """
    emg = np.asarray(emg)
    if emg.ndim != 2 or emg.shape[1] != MYO_CHANNELS or len(emg) == 0:
        raise ValueError(
            f"emg must have shape (n_samples >= 1, {MYO_CHANNELS}), got {emg.shape}"
        )
    problem = _int8_array_problem(emg)
    if problem:
        raise ValueError(f"emg must hold finite integers in {INT8_MIN}..{INT8_MAX}: {problem}")
    emg = emg.astype(np.int64)
    path = Path(path)
    if path.suffix.lower() == ".npz":
        save_npz_atomic(path, **{NPZ_KEY: emg.astype(np.int8)})
    else:
        write_text_atomic(path, "".join(",".join(map(str, row)) + "\n" for row in emg))


def make_file_emg_source(*, filename, at_end="hold", duration=None, period=MYO_PERIOD):
    """Replays a raw sEMG recording, one row per period.

    .. pydrake_system::

        name: emg_source
        output_ports:
        - emg

    ``emg`` (8, MYO units): row k of the recording (``load_emg_recording``) from t = k *
    period until the next sample instant, zero before the first; the file is read and
    checked when the diagram is built, so a malformed file fails there, never
    mid-simulation.

    Inside: ``recording`` (Drake's ``TrajectorySource`` of the rows, each held from a
    quarter period before its instant) and ``hold`` (Drake's ``ZeroOrderHold``, sampling it
    at t_k = k * period, offset 0). After the last row, ``at_end="hold"`` keeps outputting
    it; ``at_end="loop"`` starts again from the first row, up to ``duration`` seconds (the
    trajectory is the recording repeated that long, then holds).

    Parameters
    ----------
    filename : str or Path
        CSV or NPZ recording (see ``load_emg_recording``).
    at_end : {"hold", "loop"}
    duration : float, optional
        Seconds to loop over; required with ``at_end="loop"``.
    period : float
        Sample period in s (MYO: 1/200).

    Returns
    -------
    Diagram
        Named ``emg_source``; output port ``emg``.
    """
    if at_end not in ("hold", "loop"):
        raise ValueError(f"at_end must be 'hold' or 'loop', got {at_end!r}")
    period = as_scalar("period", period)
    recording = load_emg_recording(filename).astype(float)
    if at_end == "loop":
        if duration is None:
            raise ValueError("at_end='loop' needs duration= (seconds to loop over)")
        samples = math.ceil(as_scalar("duration", duration) / period) + 1
        recording = np.resize(recording, (max(samples, len(recording)), MYO_CHANNELS))
    builder = DiagramBuilder()
    rows = builder.AddNamedSystem("recording", held_samples(recording, period))
    hold = builder.AddNamedSystem("hold", ZeroOrderHold(period, MYO_CHANNELS))
    builder.Connect(rows.get_output_port(), hold.get_input_port())
    builder.ExportOutput(hold.get_output_port(), "emg")
    diagram = builder.Build()
    diagram.set_name("emg_source")
    return diagram
