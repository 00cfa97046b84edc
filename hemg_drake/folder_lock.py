"""One writer per folder: an OS lock (``flock``) on the folder, held for a whole command.

A command that writes a folder holds an exclusive lock on it; one that only reads a run
holds a shared one. A second writer is refused at once, in one line naming the holder's PID
(read from ``/proc/locks`` where there is one). The lock dies with its process, so a killed
command never leaves a folder locked.

The lock is on the folder itself (its inode), not on a file in it: a stage swaps in a new
version of the folder (:mod:`hemg_drake.run_folder`), and :meth:`FolderLock.moved_to` carries
the lock to the new version before it takes the folder's name, so there is no moment at
which the name is unlocked. Locks are re-entrant within a process (``run_demo`` locks a run
for the whole demo, each stage locks it again).
"""

import contextlib
import fcntl
import os
from pathlib import Path

# The locks this process holds, by the folder's resolved path.
_HELD = {}


class FolderBusy(ValueError):
    """Another process is writing the folder (or reading it, for a writer)."""


def _holder(fd):
    """The PID holding a lock on the inode of ``fd`` (from /proc/locks), or None."""
    st = os.fstat(fd)
    try:
        lines = Path("/proc/locks").read_text().splitlines()
    except OSError:
        return None
    for line in lines:
        fields = line.split()
        # "1: FLOCK  ADVISORY  WRITE 7381 fe:00:5398780 0 EOF" (device in hex, inode decimal)
        if len(fields) >= 6 and fields[1] == "FLOCK" and fields[4].isdigit():
            major, minor, inode = fields[5].split(":")
            if int(inode) == st.st_ino and os.makedev(int(major, 16), int(minor, 16)) == st.st_dev:
                return int(fields[4])
    return None


class FolderLock:
    """A held lock on a folder (see :func:`folder_lock`)."""

    def __init__(self, path, fd, shared):
        self.path, self.fd, self.shared, self.depth = path, fd, shared, 1

    def moved_to(self, fd):
        """Hold the lock through ``fd`` (a new version of the folder, already locked by this
        process) from now on, and release the old one."""
        old, self.fd = self.fd, fd
        os.close(old)


def _open_locked(path, shared):
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
    except BlockingIOError:
        pid = _holder(fd)
        os.close(fd)
        who = f"PID {pid}" if pid is not None else "another process"
        doing = "reading" if shared else "writing"
        raise FolderBusy(
            f"{path}: another hemg-drake command ({who}) is using it; wait for it to finish "
            f"or choose another folder ({doing} needs it to itself)"
            if not shared
            else f"{path}: another hemg-drake command ({who}) is writing it; wait for it to finish"
        ) from None
    except BaseException:
        os.close(fd)
        raise
    return fd


def lock_new_folder(path):
    """Create the folder ``path`` (which must not exist) and hold an exclusive lock on it;
    returns the descriptor (the caller closes it, or hands it to :meth:`FolderLock.moved_to`)."""
    os.mkdir(path)
    return _open_locked(path, shared=False)


@contextlib.contextmanager
def folder_lock(path, *, shared=False):
    """Hold a lock on the folder ``path`` (which must exist) for the block.

    Raises :class:`FolderBusy` (a ValueError: one line) if another process holds a
    conflicting lock. Re-entrant in one process; a shared lock inside an exclusive one is
    the exclusive one. Yields the :class:`FolderLock`.
    """
    key = os.path.realpath(path)
    held = _HELD.get(key)
    if held is not None:
        if held.shared and not shared:
            raise FolderBusy(f"{path}: this command reads it and cannot also write it")
        held.depth += 1
        try:
            yield held
        finally:
            held.depth -= 1
        return
    for _ in range(10):
        fd = _open_locked(key, shared)
        # Another command may have swapped in a new version between open and flock: then
        # the lock is on the old one. Lock again until the name and the lock agree.
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(key))
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    else:
        raise FolderBusy(f"{path}: keeps being replaced by another command; try again")
    lock = _HELD[key] = FolderLock(key, fd, shared)
    try:
        yield lock
    finally:
        del _HELD[key]
        os.close(lock.fd)
