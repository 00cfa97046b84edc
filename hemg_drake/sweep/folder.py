"""A sweep's folder: the record that makes it a sweep's (``sweep.json``), the checks before a
sweep writes there, the lock held while it does, and what an interrupted sweep leaves.

A sweep writes only into a new or empty folder, or into one holding ``sweep.json`` (a
folder it wrote). It holds an exclusive :func:`~hemg_drake.folder_lock.folder_lock` on the
folder for the whole command, so a second sweep on the same folder is refused in one line
naming the first one's PID. ``--resume`` continues only the sweep that wrote the folder: the
same base scenario (its text), ``set``, ``steps`` and ``heldout`` (axes, seeds and metrics
may grow: a trial's id is the digest of its overrides). The sweep removes only what it
names as its own: the temporary folders (``.tmp-*``, and ``..tmp-*`` built beside them) of
trials and cache entries that did not finish, and, when it made the folder and fails before
any trial finished, the folder.
"""

import contextlib
import hashlib
import json
import os
import re
import shutil
from pathlib import Path

from hemg_drake.fileio import write_text_atomic
from hemg_drake.sweep.trial import TRIAL_FILE

MARKER = "sweep.json"
# fileio.atomic_open's temporary file of the marker (".sweep.json.<random>.tmp").
_MARKER_TMP = re.compile(rf"^\.{re.escape(MARKER)}\.[^/]+\.tmp$")
# The fields of a sweep that its trials' results depend on beyond their overrides.
_SAME = ("scenario_sha256", "set", "steps", "heldout")


def identity(spec, scenario_text):
    """What a resumed sweep must share with the sweep that wrote the folder."""
    return dict(
        scenario_sha256=hashlib.sha256(scenario_text.encode()).hexdigest(),
        set=list(spec.set), steps=list(spec.steps), heldout=int(spec.heldout),
    )  # fmt: skip


def finished_trials(out):
    """The trial folders of ``out`` that hold a record (done or failed)."""
    trials_dir = Path(out) / "trials"
    if not trials_dir.is_dir():
        return []
    return sorted(p.name for p in trials_dir.iterdir()
                  if not p.name.startswith(".") and (p / TRIAL_FILE).is_file())  # fmt: skip


def _check(out, wanted, resume):
    """Raise ValueError unless a sweep may write the existing folder ``out`` now."""
    names = [n for n in os.listdir(out) if not _MARKER_TMP.match(n)]
    if not names:
        if resume:
            raise ValueError(f"{out}: no sweep to resume there (no {MARKER}); run without --resume")
        return
    marker = out / MARKER
    if not marker.is_file():
        raise ValueError(
            f"{out}: holds files hemg-drake sweep did not write (no {MARKER}): give a new or "
            "empty folder for the sweep"
        )
    try:
        recorded = json.loads(marker.read_text(encoding="utf-8"))["identity"]
    except (OSError, ValueError, KeyError, TypeError):
        raise ValueError(
            f"{marker}: not a sweep record (unreadable JSON); give another --out"
        ) from None
    if resume:
        differ = [k for k in _SAME if recorded.get(k) != wanted[k]]
        if differ:
            what = ", ".join("the base scenario's text" if k == "scenario_sha256" else repr(k)
                             for k in differ)  # fmt: skip
            raise ValueError(
                f"{out}: was written by another sweep (its {what} differ): --resume goes "
                "on with the same sweep only (its axes, seeds and metrics may grow); choose "
                "another --out"
            )
    elif finished_trials(out):
        raise ValueError(
            f"{out}: holds a sweep's trials already: pass --resume to continue it, or "
            "choose another --out"
        )


def tidy(out):
    """Remove the temporary folders of trials and cache entries that did not finish, and
    the temporary file of a ``sweep.json`` being written."""
    for name in os.listdir(out):
        if _MARKER_TMP.match(name):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(Path(out) / name)
    for folder in (Path(out) / "trials", Path(out) / "cache"):
        if folder.is_dir():
            # A trial's or cache entry's folder being built (".tmp-<name>-<pid>"), and the
            # next version of one that a run-folder stage builds beside it (".<that>.*").
            for stale in folder.glob(".tmp-*"):
                shutil.rmtree(stale, ignore_errors=True)
            for stale in folder.glob("..tmp-*"):
                shutil.rmtree(stale, ignore_errors=True)


@contextlib.contextmanager
def sweep_folder(out, spec, scenario_text, spec_text, *, resume):
    """Hold the sweep folder ``out`` for the block: made if new, locked, checked, its stale
    temporaries removed, ``sweep.json`` and ``sweep.yaml`` written.

    On any exception (Ctrl-C included) the unfinished trials' temporaries are removed, and
    a folder this call made is removed again if no trial finished in it.
    """
    from hemg_drake.folder_lock import folder_lock

    out = Path(out)
    wanted = identity(spec, scenario_text)
    made = []
    for folder in reversed([out, *out.parents]):
        if not folder.exists():
            folder.mkdir()
            made.append(folder)
    try:
        with folder_lock(out):
            _check(out, wanted, resume)
            try:
                tidy(out)
                # The record first: killed at any moment, the folder is empty or a sweep's.
                record = dict(tool="hemg-drake sweep", identity=wanted)
                write_text_atomic(out / MARKER, json.dumps(record, indent=2) + "\n")
                write_text_atomic(out / "sweep.yaml", spec_text)
                (out / "trials").mkdir(exist_ok=True)
                yield out
            except BaseException:
                tidy(out)
                if made and not finished_trials(out):
                    shutil.rmtree(out, ignore_errors=True)
                raise
    except BaseException:
        for folder in reversed(made):
            with contextlib.suppress(OSError):
                folder.rmdir()  # only if empty: nothing of anyone else's goes
        raise
