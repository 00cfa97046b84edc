"""Demonstrations in robomimic's HDF5 layout, so other learning code reads them.

robomimic (ARISE-Initiative/robomimic, "Datasets > Overview > Dataset Structure") reads::

    data                      group; attrs total (samples in all demos), env_args (JSON:
                              env_name, type, env_kwargs)
    data/demo_<i>             group per demonstration, i = 0 .. C-1; attr num_samples
    data/demo_<i>/obs/<key>   (N, D) per observation key
    data/demo_<i>/next_obs/<key>   the observation one step later
    data/demo_<i>/actions     (N, A)
    data/demo_<i>/rewards     (N,)
    data/demo_<i>/dones       (N,)

A hemg_drake demonstration maps onto it at its log period (N = T samples):

- ``obs``: ``p_WE``, ``v_WE``, ``p_MS``, ``f_WE`` (N, 3) and ``gain``, ``envelope``,
  ``activation`` (N, 1), SI units (m, m/s, N; K as logged); for a dataset that logged the
  arm's joints, also robosuite's proprioception keys, which robomimic's configs name:
  ``robot0_joint_pos`` (N, 7, rad, right_s0 ... right_w2), ``robot0_eef_pos`` (N, 3, the
  tool point p_WE again) and ``robot0_eef_quat`` (N, 4), the tool frame's orientation in W
  as a unit quaternion in robosuite's order **[x, y, z, w]** (``convert_quat(..., to="xyzw")``
  in its robots' ``eef_quat`` sensor; Drake's order is [w, x, y, z]), signs continuous over
  the dataset (:func:`~hemg_drake.learning.demos.tool_quaternions`). A dataset recorded
  before they were logged is exported without them, with a warning. ``next_obs`` repeats
  the last sample at the end, as robomimic's converters do;
- ``actions`` (N, 4): what the operator commanded the slave, ``[p_WE_desired (m, W), K]``
  (the CLIK's reference and the stiffness of eq. 22), in SI units, not normalised;
- ``rewards``: 0 (no task reward is defined here); ``dones``: 1 on the last sample;
- ``env_args``: ``{"env_name": "hemg_drake/<task>", "type": 2, "env_kwargs": {...}}``
  (2 is robomimic's generic gym type; there is no robomimic environment to roll out in,
  so train with rollouts disabled).

Beside robomimic's keys, which its loaders ignore, each demo keeps what a round trip
needs: attr ``seed``, ``time`` (N,), ``emg/{time, emg, muscle_activation}`` at the
MYO's 200 Hz, ``R_WE`` (N, 3, 3) (the tool's rotation matrices, exact, when logged) and,
for a demonstration recorded at a placement, its task frames
``task_frames/A`` (F, 3, 3) and ``task_frames/b`` (F, 3) (the robot's base and the scene
frame T in W, what the TP-HSMM learns with); ``data`` keeps the dataset's metadata as JSON
in attr ``hemg_drake_metadata``.
:func:`load_robomimic` reads the file back into :class:`Demonstration` objects.
"""

import errno
import json
import os
import warnings
from pathlib import Path

import numpy as np

from hemg_drake.fileio import write_bytes_atomic
from hemg_drake.learning.demos import Demonstration, tool_quaternions

_INSTALL_HINT = "install the optional extra: pip install 'hemg-drake[export]'"
# Observation keys, with the Demonstration field each comes from.
OBS_KEYS = ("p_WE", "v_WE", "p_MS", "f_WE", "gain", "envelope", "activation")
# robosuite's proprioception keys, written when the dataset logged the arm's joints.
ARM_OBS_KEYS = ("robot0_joint_pos", "robot0_eef_pos", "robot0_eef_quat")
NO_ARM_NOTE = (
    "the demonstrations do not hold the arm's joint positions and the tool's orientation "
    "(recorded before they were logged): exported without {keys}"
)
ACTION_KEYS = ("p_WE_desired", "gain")
EMG_KEYS = {"time": "emg_time", "emg": "emg", "muscle_activation": "muscle_activation"}
# robomimic's EnvType.GYM_TYPE: the generic type, for an environment it cannot create.
GYM_TYPE = 2
METADATA_ATTR = "hemg_drake_metadata"


def _h5py():
    try:
        import h5py
    except ImportError as error:
        raise ModuleNotFoundError(f"robomimic export needs h5py ({_INSTALL_HINT})") from error
    return h5py


def _column(array):
    array = np.asarray(array, dtype=float)
    return array[:, np.newaxis] if array.ndim == 1 else array


def _write(group, name, array):
    # gzip (h5py, and so robomimic, decompresses transparently): two pin demonstrations
    # take 366 kB instead of 438 kB.
    group.create_dataset(name, data=array, compression="gzip", shuffle=True)


def _env_args(metadata, arm):
    task = metadata.get("task", "unknown")
    kwargs = {key: metadata[key] for key in ("task", "log_period") if key in metadata}
    kwargs["action_keys"] = list(ACTION_KEYS)
    kwargs["obs_keys"] = [*OBS_KEYS, *(ARM_OBS_KEYS if arm else ())]
    return {"env_name": f"hemg_drake/{task}", "type": GYM_TYPE, "env_kwargs": kwargs}


def export_robomimic(path, demos, metadata=None):
    """Write demonstrations to ``path`` in robomimic's HDF5 layout, atomically.

    Parameters
    ----------
    path : path-like
        The ``.hdf5`` file; replaced atomically if it exists.
    demos : sequence of Demonstration, at least one.
    metadata : dict, optional
        The dataset's metadata (``load_dataset``), JSON-serialisable; kept in the file.

    Returns
    -------
    int, the number of samples written (``data.attrs["total"]``).
    """
    h5py = _h5py()
    demos = list(demos)
    if not demos or not all(isinstance(d, Demonstration) for d in demos):
        raise ValueError("export_robomimic needs a non-empty list of Demonstration")
    metadata = dict(metadata or {})
    try:
        metadata_text = json.dumps(metadata, sort_keys=True)
    except TypeError as error:
        raise ValueError(f"metadata must be JSON-serialisable: {error}") from None
    path = Path(path)
    # HDF5 builds the file in memory (its core driver, no backing store) and the bytes go to
    # a temporary file beside ``path``, renamed over it: a full disk is then an OSError of
    # plain file I/O. Measured: HDF5 writing to a full disk itself, through a Python file
    # object or by name, crashed (exit 139, hundreds of lines of h5py tracebacks) while
    # closing its objects.
    with h5py.File(path.name, "w", driver="core", backing_store=False) as f:
        total = _write_demos(f, demos, metadata, metadata_text)
        f.flush()
        image = f.id.get_file_image()
    try:
        write_bytes_atomic(path, image)
    except OSError as error:
        raise write_error(path, error) from None
    return total


def write_error(path, error):
    """An OSError naming ``path`` (the output) for an error while writing it (a full disk,
    an I/O error): one line, whatever the library's message."""
    number = getattr(error, "errno", None)
    text = str(error)
    if number is None:
        for code in (errno.ENOSPC, errno.EIO, errno.EDQUOT, errno.EFBIG):
            if os.strerror(code) in text or f"errno = {code}," in text:
                number = code
                break
    reason = os.strerror(number) if number else (text.splitlines() or ["I/O error"])[0]
    return OSError(number, f"cannot write it: {reason}; nothing was written", str(path))


def _write_demos(f, demos, metadata, metadata_text):
    total = 0
    data = f.create_group("data")
    quats = tool_quaternions(demos)  # None unless every demonstration has q and R_WE
    if quats is None:
        warnings.warn(NO_ARM_NOTE.format(keys=", ".join(ARM_OBS_KEYS)), stacklevel=3)
    for i, demo in enumerate(demos):
        group = data.create_group(f"demo_{i}")
        n = len(demo)
        obs = {key: _column(getattr(demo, key)) for key in OBS_KEYS}
        if quats is not None:
            obs["robot0_joint_pos"], obs["robot0_eef_pos"] = demo.q, demo.p_WE
            obs["robot0_eef_quat"] = quats[i][:, [1, 2, 3, 0]]  # [w, x, y, z] -> [x, y, z, w]
            _write(group, "R_WE", demo.R_WE)
        for key, array in obs.items():
            _write(group, f"obs/{key}", array)
            _write(group, f"next_obs/{key}", np.concatenate([array[1:], array[-1:]]))
        actions = np.column_stack([getattr(demo, key) for key in ACTION_KEYS])
        _write(group, "actions", actions)
        _write(group, "rewards", np.zeros(n))
        dones = np.zeros(n)
        dones[-1] = 1.0
        _write(group, "dones", dones)
        _write(group, "time", demo.time)
        for key, field in EMG_KEYS.items():
            _write(group, f"emg/{key}", getattr(demo, field))
        if demo.frame_A is not None:
            _write(group, "task_frames/A", demo.frame_A)
            _write(group, "task_frames/b", demo.frame_b)
        group.attrs["num_samples"] = n
        group.attrs["seed"] = demo.seed
        total += n
    data.attrs["total"] = total
    data.attrs["env_args"] = json.dumps(_env_args(metadata, quats is not None))
    data.attrs[METADATA_ATTR] = metadata_text
    return total


def _demo_names(path, data):
    names = [name for name in data if name.startswith("demo_")]
    try:
        return sorted(names, key=lambda name: int(name[len("demo_"):]))
    except ValueError:
        raise ValueError(f"{path}: group names must be demo_<integer>, got {names}") from None


def _read(path, group, key):
    if key not in group:
        raise ValueError(f"{path}: {group.name}/{key} is missing")
    return np.asarray(group[key][()])


def load_robomimic(path):
    """Read a file written by :func:`export_robomimic` back into demonstrations.

    Returns
    -------
    demos : list of Demonstration
    metadata : dict
        The metadata the file was exported with.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Not an HDF5 file, or not one this module wrote (a missing group, dataset or
        attribute, a length that disagrees with ``num_samples``): the message names it.
    """
    h5py = _h5py()
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"robomimic file not found: {path}")
    try:
        f = h5py.File(path, "r")
    except OSError as error:
        raise ValueError(f"{path}: not a readable HDF5 file ({error})") from None
    with f:
        if "data" not in f:
            raise ValueError(f"{path}: no 'data' group; not a robomimic dataset")
        data = f["data"]
        if METADATA_ATTR not in data.attrs:
            raise ValueError(
                f"{path}: data has no {METADATA_ATTR!r} attribute; not exported by hemg_drake"
            )
        metadata = json.loads(data.attrs[METADATA_ATTR])
        demos = []
        for name in _demo_names(path, data):
            group = data[name]
            n = int(group.attrs.get("num_samples", -1))
            fields = {"time": _read(path, group, "time")}
            for key in OBS_KEYS:
                array = _read(path, group, f"obs/{key}")
                fields[key] = array[:, 0] if array.ndim == 2 and array.shape[1] == 1 else array
            actions = _read(path, group, "actions")
            if actions.ndim != 2 or actions.shape[1] != 4:
                raise ValueError(f"{path}: {group.name}/actions must have shape (N, 4)")
            fields["p_WE_desired"] = actions[:, :3]
            for key, field in EMG_KEYS.items():
                fields[field] = _read(path, group, f"emg/{key}")
            if "task_frames" in group:
                fields["frame_A"] = _read(path, group, "task_frames/A")
                fields["frame_b"] = _read(path, group, "task_frames/b")
            if "R_WE" in group:
                fields["R_WE"] = _read(path, group, "R_WE")
                fields["q"] = _read(path, group, "obs/robot0_joint_pos")
            if len(fields["time"]) != n:
                raise ValueError(
                    f"{path}: {group.name} has {len(fields['time'])} samples, "
                    f"num_samples says {n}"
                )
            try:
                demos.append(Demonstration(seed=int(group.attrs.get("seed", 0)), **fields))
            except (TypeError, ValueError) as error:
                raise ValueError(f"{path}: {group.name}: {error}") from None
    if not demos:
        raise ValueError(f"{path}: no demo_<i> groups in data")
    return demos, metadata
