"""Atomic file writing: a crash midway never leaves a half-written file behind."""

import contextlib
import io
import os
import signal
import tempfile
import zipfile
from pathlib import Path

import numpy as np


# Fault injection for tests/faults (off unless set): HEMG_DRAKE_FAULT_AT=N kills the
# process (SIGKILL) at the N-th fault point, or with HEMG_DRAKE_FAULT_ERRNO=E raises an
# OSError of errno E there that names no file (as a failing write may);
# HEMG_DRAKE_FAULT_LOG=FILE appends each point's label there, so a harness can count them.
_FAULTS = {"count": 0}


def fault_point(label):
    """A moment at which a crash must leave every folder consistent (file writes, renames,
    the swap of a run folder's versions). No-op unless the test variables above are set."""
    at, log = os.environ.get("HEMG_DRAKE_FAULT_AT"), os.environ.get("HEMG_DRAKE_FAULT_LOG")
    if at is None and log is None:
        return
    _FAULTS["count"] += 1
    if log is not None:
        with open(log, "a", encoding="utf-8") as f:
            f.write(f"{_FAULTS['count']} {label}\n")
    if at is not None and _FAULTS["count"] == int(at):
        code = os.environ.get("HEMG_DRAKE_FAULT_ERRNO")
        if code is not None:
            raise OSError(int(code), os.strerror(int(code)))
        os.kill(os.getpid(), signal.SIGKILL)


@contextlib.contextmanager
def atomic_open(path, mode="w", **kwargs):
    """Open a temporary file beside ``path``; on success rename it over ``path``.

    The rename is atomic on POSIX, so readers see either the old file or the
    complete new one. On an exception the temporary file is removed and
    ``path`` is left untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        # mkstemp makes the file private (0600); give it the mode open() would have.
        os.chmod(tmp, 0o666 & ~_umask())
        with os.fdopen(fd, mode, **kwargs) as f:
            yield f
            fault_point(f"write {path.name}")
            f.flush()
            os.fsync(f.fileno())
        fault_point(f"rename {path.name}")
        os.replace(tmp, path)
    except BaseException as error:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(error, OSError) and error.filename is None:
            # A write's error (a full disk) names no file: name the one being written.
            raise OSError(error.errno, error.strerror or str(error), str(path)) from None
        raise


def named_as_moved(error, built, final):
    """``error`` (an OSError raised while a folder was built at ``built`` to become ``final``:
    a full disk, an I/O error) naming its file as it would be in ``final`` (``built``'s name
    means nothing to a person; ``final`` when it names no file), saying ``final`` is as it
    was. Errors naming other files, and ones without an errno, are returned as they are."""
    if error.errno is None:
        return error
    shown = None
    for name in (error.filename2, error.filename):  # shutil.copy2 names the copy second
        if name is not None:
            rel = os.path.relpath(os.path.realpath(name), os.path.realpath(built))
            if rel != os.pardir and not rel.startswith(os.pardir + os.sep):
                shown = Path(final) if rel == "." else Path(final) / rel
                break
    if shown is None:
        if error.filename is not None:
            return error
        shown = Path(final)
    reason = error.strerror or str(error) or type(error).__name__
    return OSError(error.errno, f"{reason}; nothing in {final}/ was changed", str(shown))


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text_atomic(path, text):
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_open(path, "w", encoding="utf-8") as f:
        f.write(text)


def write_bytes_atomic(path, data):
    """Write ``data`` to ``path`` atomically."""
    with atomic_open(path, "wb") as f:
        f.write(data)


def save_npz_atomic(path, **arrays):
    """``np.savez_compressed`` to ``path`` atomically (no ``.npz`` suffix is added)."""
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    write_bytes_atomic(path, buffer.getvalue())


def load_npz(path, *, kind):
    """All arrays of an NPZ file, as a dict; no pickles.

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` naming the
    file and what it should have been (``kind``, e.g. "HSMM model") for one that
    numpy cannot read (truncated, not a zip archive, pickled objects).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{kind} file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as archive:
            return {name: archive[name] for name in archive.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:
        # numpy's own message may advise allow_pickle=True: never pass that advice on.
        reason = "not an NPZ archive (neither a zip archive nor numpy data)" if "pickle" in str(
            error
        ) else _reason(error)
        raise ValueError(f"{path}: not a readable NPZ file ({kind} expected): {reason}") from None


def _reason(error):
    if isinstance(error, zipfile.BadZipFile):
        return "not a zip archive (truncated, or another kind of file)"
    return (str(error).strip().splitlines() or [type(error).__name__])[0]


def read_yaml_text(path, *, kind):
    """The UTF-8 text of a YAML file, or a one-line error naming it and what it should be.

    ``kind`` names the file in the messages ("scenario", "sweep"): a folder is a ValueError
    ("is a folder, not a scenario file"), a missing file a FileNotFoundError, and bytes that
    are not UTF-8 a ValueError naming the first bad byte.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: is a folder, not a {kind} file (a .yaml file)")
    if not path.is_file():
        raise FileNotFoundError(f"{kind} file not found: {path}")
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as error:
        raise ValueError(f"{path}: not UTF-8 text (byte {error.start}): not a YAML file") from None
