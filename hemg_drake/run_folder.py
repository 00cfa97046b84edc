"""A run folder: one task's files, which stage wrote each, and from what.

``runs/NAME/`` holds the outputs of three stages, each made from the one before::

    demonstrate   dataset.npz, replay_<c>.html, demonstrations.png, fig6_emg.png,
                  interaction.npz
    learn         model.npz, state_activations.png              (from dataset.npz)
    reproduce     reproduction.html/.npz, metrics.json, figures (from model.npz)

Provenance lives in ``manifest.json``: for each finished stage, the SHA-256 of every file
it wrote and of every file it read. A folder is a run folder if it has a manifest; the tool
writes only into a new or empty folder or a run folder, and removes only files a manifest
lists (its own outputs).

A stage never edits the folder in place (:meth:`RunFolder.transaction`): it builds the new
version of the whole folder beside it (``.NAME.hemg-drake-new-PID``: hard links to every
file it keeps, its own outputs, the manifest last), then swaps the two folders in one atomic
``renameat2(RENAME_EXCHANGE)``. A failure, Ctrl-C, SIGTERM or SIGKILL at any moment leaves
the previous folder exactly as it was; the next command removes what was left beside it. The
files a stage replaces are its own older outputs and those of the stages after it, and
reproductions in sub-folders made from a model or dataset it replaces (``start_offset/``,
``reproduce --out runs/pin/lqr``): they no longer match. A user's own files are kept.

A command holds an exclusive lock on the folder it writes (:mod:`hemg_drake.folder_lock`):
a second writer is refused in one line.

A reproduction written to another folder (``reproduce --out``) gets a manifest of its own
there, naming the model and dataset it came from (by path and hash).
"""

import contextlib
import json
import os
import shutil
import signal
from pathlib import Path

from hemg_drake.fileio import fault_point, named_as_moved, write_text_atomic
from hemg_drake.folder_lock import folder_lock, lock_new_folder
from hemg_drake.folder_versions import (
    MANIFEST,
    NEW,
    OLD,
    copy_kept,
    discard_old,
    exchange,
    file_hash,
    listed_files,
    read_manifest,
    recover,
)

DATASET, MODEL = "dataset.npz", "model.npz"
STAGES = ("demonstrate", "learn", "reproduce")
# Signals held back while a stage swaps its new version in.
_STOPS = {signal.SIGINT, signal.SIGTERM}
# Files each stage writes (glob patterns, relative to the folder).
OUTPUTS = {
    "demonstrate": (
        DATASET, "replay_*.html", "inputs_*.npz", "demonstrations.png", "fig6_emg.png",
        "interaction.npz",
    ),
    # The diagrams (run_demo) are drawn with the model.
    "learn": (MODEL, "state_activations.png", "demonstration_diagram.svg",
              "demonstration_diagram.dot", "reproduction_diagram.svg", "reproduction_diagram.dot"),
    "reproduce": (
        "reproduction.html", "reproduction.npz", "metrics.json", "fig8_reproduction.png",
        "fig10_reproduction.png", "fig11_strokes.png", "placements.png",
    ),
}  # fmt: skip
# The files of a stage that later stages read: replacing them invalidates what was made
# from them (in this folder and in reproductions in its sub-folders).
READ_BY_LATER = {"demonstrate": (DATASET,), "learn": (MODEL,), "reproduce": ()}
# Sub-folder of the full demo's placements run (pipeline.placement_demo): a run of its own,
# made from this folder's scenario, replaced with the folder's demonstrations.
PLACEMENTS_FOLDER = "placements"


class RunFolder:
    """A run folder and its manifest.

    Parameters
    ----------
    path : path-like
    create : bool
        Create the folder if missing; otherwise a missing folder is a FileNotFoundError.
    final : path-like, optional
        For the version of a folder a stage is building: the folder it will become (paths
        in the manifest are named relative to it).
    """

    def __init__(self, path, *, create=False, final=None):
        self.path = Path(path)
        self.final = Path(final) if final is not None else self.path
        if self.path.exists() and not self.path.is_dir():
            raise ValueError(f"{self.path}: is a file, not a run folder")
        if create:
            self.path.mkdir(parents=True, exist_ok=True)
        elif not self.path.is_dir():
            raise FileNotFoundError(f"run folder not found: {self.path}")

    @classmethod
    def output(cls, path):
        """A folder a stage writes: it may not exist yet (:meth:`transaction` makes it)."""
        self = cls.__new__(cls)
        self.path = self.final = Path(path)
        if self.path.exists() and not self.path.is_dir():
            raise ValueError(f"{self.path}: is a file, not a run folder")
        return self

    def shown(self, path):
        """Where ``path``, written into this version of the folder, will be once it is in
        place (the name to show a person)."""
        return self.final / Path(path).relative_to(self.path)

    def __truediv__(self, name):
        return self.path / name

    @property
    def dataset(self):
        return self.path / DATASET

    @property
    def model(self):
        return self.path / MODEL

    read_manifest = staticmethod(read_manifest)

    def manifest(self):
        """The manifest's entries by stage ({} for a folder without one)."""
        return self.read_manifest(self.path / MANIFEST)

    def is_run(self):
        """Whether the folder has a manifest (the tool made it)."""
        return (self.path / MANIFEST).is_file()

    def _write_manifest(self, entries):
        write_text_atomic(self.path / MANIFEST, json.dumps(entries, indent=2, sort_keys=True) + "\n")

    def takes(self):
        """Whether the dataset holds takes a person recorded (``teleop``)."""
        return self.manifest().get("demonstrate", {}).get("command") == "teleop"

    def check_writable(self, stage):
        """Raise ValueError unless ``stage`` may write here: a new or empty folder, or a run
        folder in which no file the stage would write is a file the tool did not write."""
        if not self.path.exists():
            return
        present = [n for n in os.listdir(self.path) if not n.startswith(f".{NEW}")]
        if not self.is_run():
            if present:
                raise ValueError(
                    f"{self.path}: holds files hemg-drake did not write (no {MANIFEST}): "
                    "give a new or empty folder"
                )
            return
        listed = listed_files(self.path)
        for name in STAGES[STAGES.index(stage) :]:
            for pattern in OUTPUTS[name]:
                for path in sorted(self.path.glob(pattern)):
                    if path.name not in listed:
                        raise ValueError(
                            f"{path}: not written by hemg-drake (no stage in {MANIFEST} lists "
                            f"it) and the {stage} stage writes that name: move it away first"
                        )

    def _dropped(self, stage, keep_own):
        """Relative paths that the new version of the folder does not keep (the outputs of
        the stages redone, the manifest), sub-folders made from a file replaced, and the
        manifest entries kept."""
        redone = STAGES[STAGES.index(stage) + (1 if keep_own else 0) :]
        entries = self.manifest()
        kept = {name: entry for name, entry in entries.items() if name not in redone}
        dropped = {MANIFEST}
        for name in redone:
            dropped.update(entries.get(name, {}).get("files", {}))
        # The files later stages read that this stage rewrites (a take rewrites the dataset).
        replaced = {
            str(self.final.resolve() / f)
            for name in STAGES[STAGES.index(stage) :] for f in READ_BY_LATER[name]
        }  # fmt: skip
        folders = []
        for sub in sorted(p for p in self.path.iterdir() if p.is_dir() and not p.is_symlink()):
            sub_entries = self.read_manifest(sub / MANIFEST, strict=False)
            inputs = {
                str((self.final.resolve() / sub.name / i).resolve())
                for entry in sub_entries.values() for i in entry.get("inputs", {})
            }  # fmt: skip
            derived = sub.name == PLACEMENTS_FOLDER and "demonstrate" in redone
            if sub_entries and (derived or inputs & replaced):
                folders.append(sub.name)
        return dropped, folders, kept

    @contextlib.contextmanager
    def transaction(self, stage, *, keep_own=False, progress=None):
        """Build the folder's next version for ``stage`` beside it; swap it in when the block
        ends without error.

        Yields a :class:`RunFolder` on the new version: the kept files are there (hard
        links), and the block writes the stage's outputs there and calls :meth:`finish` last.
        Kept: everything but the outputs of ``stage`` (unless ``keep_own``: a take added to
        the takes) and of the stages after it, and sub-folders made from a file it replaces.
        If the block raises (or the process dies), the folder is left exactly as it was.
        """
        target = Path(os.path.realpath(self.path))
        here = Path(os.getcwd())
        if here == target or target in here.parents:
            # The swap would leave the shell in the replaced (deleted) version.
            raise ValueError(
                f"{self.path}: is the folder this command runs in (or holds it); a stage "
                f"replaces the folder whole: run it from outside (cd {target.parent})"
            )
        made = [p for p in (target, *target.parents) if not p.exists()]
        target.mkdir(parents=True, exist_ok=True)
        staging, swapped = target.parent / f".{target.name}.{NEW}-{os.getpid()}", False
        try:
            with folder_lock(target) as lock:
                recover(target)
                folder = RunFolder(target)
                folder.check_writable(stage)
                if stage == "demonstrate" and not keep_own and folder.takes():
                    raise ValueError(
                        f"{target}: holds takes a person recorded (hemg-drake teleop), which "
                        "this would replace: give another folder"
                    )
                dropped, folders, entries = folder._dropped(stage, keep_own)
                if staging.exists():
                    shutil.rmtree(staging)
                fd = lock_new_folder(staging)
                try:
                    os.chmod(staging, os.stat(target).st_mode & 0o7777)
                    fault_point("staging made")
                    removed = copy_kept(target, staging, dropped, folders)
                    fault_point("kept files linked")
                    new = RunFolder(staging, final=target)
                    new.removed = removed
                    if entries:
                        new._write_manifest(entries)
                    if removed and progress is not None:
                        progress(f"replacing {len(removed)} file(s) of the older run in {target}/ "
                                 "once this one is complete")  # fmt: skip
                    yield new
                    if new.manifest().get(stage) in (None, entries.get(stage)):
                        raise RuntimeError(f"the {stage} stage did not record its files")
                    fault_point("before the swap")
                    # The swap and the lock's move are one step: Ctrl-C or SIGTERM waits
                    # until the new version is in place (then the old one is tidied later).
                    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, _STOPS)
                    try:
                        exchange(staging, target)
                    except BaseException:
                        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
                        raise
                except BaseException:
                    os.close(fd)
                    shutil.rmtree(staging, ignore_errors=True)
                    raise
                lock.moved_to(fd)
                swapped = True
                signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
                fault_point("swapped")
                old = target.parent / f".{target.name}.{OLD}-{os.getpid()}"
                os.rename(staging, old)
                fault_point("old version aside")
                kept = discard_old(old, target)
                if kept and progress is not None:
                    progress(f"kept {old}/: it holds files changed while this command ran")
        except BaseException as error:
            for path in made:  # only folders this call made, and only if still empty
                with contextlib.suppress(OSError):
                    path.rmdir()
            if isinstance(error, OSError) and not swapped:  # a full disk, an I/O error
                raise named_as_moved(error, staging, target) from None
            raise

    def finish(self, stage, written, *, inputs=(), command=None):
        """Record ``stage`` as done: the hashes of the files it wrote and read (paths), and
        the command that ran it (``teleop`` marks takes a person recorded)."""
        entries = self.manifest()
        if self.final != self.path:
            # A kept file is a hard link to the previous version's: one listed as written
            # must be new, or listed before with the same bytes (the takes a take keeps).
            before = entries.get(stage, {}).get("files", {})
            shared = [
                self._name(p) for p in written
                if os.stat(p).st_nlink > 1 and before.get(self._name(p)) != file_hash(p)
            ]  # fmt: skip
            if shared:
                raise RuntimeError(
                    f"the {stage} stage wrote into a file it kept ({', '.join(shared)}) "
                    "instead of a new one: use hemg_drake.fileio's atomic writers"
                )
        entries[stage] = {
            "files": {self._name(p): file_hash(p) for p in written},
            "inputs": {self._name(p): file_hash(p) for p in inputs},
        }
        if command is not None:
            entries[stage]["command"] = command
        self._write_manifest(entries)

    def _name(self, path):
        """A path as the manifest names it: relative to the folder (or to the folder this
        version will become); beside it (in its parent folder), relative too
        (``../model.npz``), so a run moved with its reproductions keeps its provenance;
        otherwise absolute."""
        path = Path(path).resolve()
        for base in (self.path, self.final):
            with contextlib.suppress(ValueError):
                return str(path.relative_to(base.resolve()))
        final = self.final.resolve()
        with contextlib.suppress(ValueError):
            path.relative_to(final.parent)
            return os.path.relpath(path, final)
        return str(path)

    def check(self, stage, path, *, run_hint):
        """Raise ValueError unless ``path`` is the file that ``stage`` recorded writing.

        ``run_hint`` is the command that makes it (named in the message).
        """
        if not Path(path).is_file():
            raise FileNotFoundError(f"no {Path(path).name} in {self.path}: run {run_hint}")
        entry = self.manifest().get(stage)
        name = self._name(path)
        if entry is None or name not in entry["files"]:
            raise ValueError(
                f"{path}: no finished '{stage}' recorded it in {self.path / MANIFEST} "
                f"(an older or interrupted run): hemg-drake repair {self.path} records the "
                f"files there, or run {run_hint}"
            )
        if file_hash(path) != entry["files"][name]:
            raise ValueError(
                f"{path}: changed since '{stage}' wrote it (its hash differs from the "
                f"manifest's): hemg-drake repair {self.path} records it as it is, or run "
                f"{run_hint}"
            )
        return entry

    def check_made_from(self, stage, source, *, run_hint):
        """Raise ValueError unless the recorded ``stage`` read ``source`` as it is now."""
        entry = self.manifest().get(stage) or {"inputs": {}}
        name = self._name(source)
        if entry["inputs"].get(name) != file_hash(source):
            raise ValueError(
                f"{self.path / MODEL if stage == 'learn' else self.path}: was not made from "
                f"this folder's {name}: run {run_hint}"
            )


def repair(path, *, check_dataset=None):
    """Rebuild the manifest of the run folder ``path`` from the files there; returns the
    names recorded by stage.

    A stage whose recorded files are all there unchanged keeps its entry. Any other stage
    whose outputs are present is recorded again as it is now (``"repaired": true``) with no
    inputs, so a model or reproduction can no longer claim to come from the dataset (learn
    and reproduce ask to be run again: they replace only the tool's own files). Takes
    (``inputs_<c>.npz``) mark the dataset as a person's, which demonstrate will not replace.
    Nothing is removed or changed but the manifest. ``check_dataset`` (path -> None, raises
    ValueError) vets a dataset before it is recorded.
    """
    folder = RunFolder(path)
    with folder_lock(folder.path):
        try:
            entries = folder.manifest()
        except ValueError:
            entries = {}  # unreadable: rebuilt whole
        recorded = {}
        for stage in STAGES:
            names = sorted({
                str(p.relative_to(folder.path))
                for pattern in OUTPUTS[stage] for p in folder.path.glob(pattern) if p.is_file()
            })  # fmt: skip
            entry = entries.get(stage)
            if entry is not None and all(
                (folder / n).is_file() and file_hash(folder / n) == h
                for n, h in entry.get("files", {}).items()
            ):
                recorded[stage] = entry
                continue
            if not names or (stage != "demonstrate" and "demonstrate" not in recorded):
                continue
            if stage == "demonstrate":
                if DATASET not in names:
                    continue
                if check_dataset is not None:
                    check_dataset(folder.dataset)
            recorded[stage] = {
                "files": {n: file_hash(folder / n) for n in names}, "inputs": {}, "repaired": True,
            }  # fmt: skip
            if stage == "demonstrate" and any(n.startswith("inputs_") for n in names):
                recorded[stage]["command"] = "teleop"
        if "demonstrate" not in recorded:
            raise ValueError(f"{folder.path}: no {DATASET} to record; nothing to repair")
        if "demo" in entries:
            recorded["demo"] = entries["demo"]
        folder._write_manifest(recorded)
    return {stage: sorted(entry["files"]) for stage, entry in recorded.items()}
