"""Versions of a folder, built beside it and swapped in whole (:mod:`hemg_drake.run_folder`).

The primitives: the atomic swap of two folders (``renameat2(RENAME_EXCHANGE)``), the copy of
the files a new version keeps (hard links), the removal of a replaced version that never
loses a file a person put there, and the tidying of what a killed command left beside a
folder (``.NAME.hemg-drake-new-PID`` being built, ``.NAME.hemg-drake-old-PID`` replaced).
"""

import ctypes
import errno
import hashlib
import json
import os
import shutil
from pathlib import Path

from hemg_drake.fileio import fault_point

MANIFEST = "manifest.json"
# The versions of a folder a stage builds beside it: .NAME.hemg-drake-new-PID (being
# built) and .NAME.hemg-drake-old-PID (the replaced version, being removed).
NEW, OLD = "hemg-drake-new", "hemg-drake-old"


def file_hash(path):
    """SHA-256 of a file's bytes, as hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_manifest(path, *, strict=True):
    """The entries of the manifest file ``path`` ({} if missing; unreadable: ValueError,
    or {} when not ``strict``)."""
    path = Path(path)
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        if not strict:
            return {}
        raise ValueError(
            f"{path}: not a readable manifest; hemg-drake repair {path.parent} rebuilds "
            "it from the files there"
        ) from None
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        if not strict:
            return {}
        raise ValueError(f"{path}: not a hemg-drake manifest (a JSON object of stages)")
    return data


def is_temporary(name):
    # fileio.atomic_open's temporary files: ".NAME.<random>.tmp"
    return name.startswith(".") and name.endswith(".tmp")


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _renameat2():
    return getattr(ctypes.CDLL(None, use_errno=True), "renameat2", None)


def exchange(a, b):
    """Swap the folders ``a`` and ``b`` in one atomic step (Linux ``renameat2``).

    Where the call or the filesystem lacks it, falls back to two renames (``b`` aside, then
    ``a`` into place): a crash between them leaves ``b`` beside, under the old name, where
    :func:`recover` puts it back.
    """
    function = _renameat2()
    if function is not None:
        if function(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
            return
        code = ctypes.get_errno()
        if code not in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP):
            raise OSError(code, os.strerror(code), str(b))
    aside = Path(b).parent / f".{Path(b).name}.{OLD}-{os.getpid()}"
    os.rename(b, aside)
    fault_point("fallback: folder aside")
    os.rename(a, b)
    os.rename(aside, a)


def _walk_files(root):
    """Relative paths of every file and symlink under ``root`` (not following links)."""
    found = []
    for base, dirs, files in os.walk(root):
        for name in files + [d for d in dirs if os.path.islink(os.path.join(base, d))]:
            found.append(os.path.relpath(os.path.join(base, name), root))
    return sorted(found)


def listed_files(folder):
    """Relative paths the manifests under ``folder`` list as written by the tool (its own
    and its sub-folders'), with the manifests themselves."""
    listed = set()
    for base, _dirs, files in os.walk(folder):
        if MANIFEST in files:
            rel = os.path.relpath(base, folder)
            prefix = "" if rel == "." else rel + os.sep
            listed.add(prefix + MANIFEST)
            for entry in read_manifest(Path(base) / MANIFEST, strict=False).values():
                listed.update(prefix + name for name in entry.get("files", {}))
    return listed


def _same_file(a, b):
    try:
        if os.path.samestat(os.lstat(a), os.lstat(b)):
            return True
        return os.path.isfile(a) and os.path.isfile(b) and file_hash(a) == file_hash(b)
    except OSError:
        return False


def discard_old(old, new):
    """Remove the replaced version ``old`` of the folder ``new``: files ``new`` still has
    (hard links, or equal bytes) and files the tool wrote (a manifest lists them) go; any
    other file (one a person put there while the command ran) is moved into ``new``. Returns
    the relative paths kept in ``old`` because ``new`` has another file of that name."""
    listed, kept = listed_files(old), []
    # The manifests go last: a crash midway leaves them naming what is still the tool's.
    for rel in sorted(_walk_files(old), key=lambda rel: os.path.basename(rel) == MANIFEST):
        fault_point(f"discard {rel}")
        path, there = Path(old) / rel, Path(new) / rel
        if rel in listed or is_temporary(path.name) or _same_file(path, there):
            path.unlink()
        elif not os.path.lexists(there):
            there.parent.mkdir(parents=True, exist_ok=True)
            os.rename(path, there)
        else:
            kept.append(rel)
    if not kept:
        shutil.rmtree(old, ignore_errors=True)
    return kept


def recover(target):
    """Tidy what an interrupted stage left beside ``target`` (call with its lock held, or
    before it exists): a version being built is removed; a replaced version is discarded
    (:func:`discard_old`), or put back if ``target`` is missing (a crash inside the two-rename
    fallback of :func:`exchange`)."""
    target = Path(target)
    for sibling in sorted(target.parent.glob(f".{target.name}.{OLD}-*")):
        if not target.exists():
            os.rename(sibling, target)
        elif sibling.is_dir():
            discard_old(sibling, target)
    for sibling in sorted(target.parent.glob(f".{target.name}.{NEW}-*")):
        if sibling.is_dir() and not _locked_elsewhere(sibling):
            shutil.rmtree(sibling, ignore_errors=True)


def _locked_elsewhere(path):
    import fcntl

    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return False
    except BlockingIOError:
        return True
    finally:
        os.close(fd)


def copy_kept(target, staging, dropped, folders):
    """Hard-link (or copy, where links fail) every file of ``target`` into ``staging`` but
    the ``dropped`` paths, the ``folders`` and temporaries; returns what is not kept."""
    removed = []
    for rel in _walk_files(target):
        top = rel.split(os.sep, 1)[0]
        if rel in dropped or top in folders or is_temporary(os.path.basename(rel)):
            if rel != MANIFEST:
                removed.append(rel)
            continue
        source, there = target / rel, staging / rel
        there.parent.mkdir(parents=True, exist_ok=True)
        if os.path.islink(source):
            os.symlink(os.readlink(source), there)
            continue
        try:
            os.link(source, there)
        except OSError:
            shutil.copy2(source, there)
    for base, dirs, _files in os.walk(target):  # empty folders a person made
        for name in dirs:
            rel = os.path.relpath(os.path.join(base, name), target)
            if rel.split(os.sep, 1)[0] not in folders:
                (staging / rel).mkdir(parents=True, exist_ok=True)
    return removed
