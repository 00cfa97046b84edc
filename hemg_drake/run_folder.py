"""A run folder: one task's files, which stage wrote each, and from what.

``runs/NAME/`` holds the outputs of three stages, each made from the one before::

    demonstrate   dataset.npz, replay_<c>.html, demonstrations.png, fig6_emg.png
    learn         model.npz, state_activations.png              (from dataset.npz)
    reproduce     reproduction.html/.npz, metrics.json, figures (from model.npz)

Provenance lives in ``manifest.json``: for each finished stage, the SHA-256 of every file
it wrote and of every file it read. A stage first removes its own old outputs and those of
the stages after it (so a folder never mixes runs, and a reproduction without a replay
leaves no old replay behind), writes its files (each atomically), and records its entry
last: a stage killed midway leaves no entry, which the next stage detects. Stale temporary
files of an interrupted atomic write (``.NAME.*.tmp``) are removed when a stage begins.

A reproduction written to another folder (``reproduce --out``) gets a manifest of its own
there, naming the model and dataset it came from.
"""

import contextlib
import hashlib
import json
import shutil
from pathlib import Path

from hemg_drake.fileio import write_text_atomic

MANIFEST = "manifest.json"
DATASET, MODEL = "dataset.npz", "model.npz"
STAGES = ("demonstrate", "learn", "reproduce")
# Files each stage writes (glob patterns, relative to the folder).
OUTPUTS = {
    "demonstrate": (
        DATASET, "replay_*.html", "inputs_*.npz", "demonstrations.png", "fig6_emg.png",
        "demonstration_diagram.svg", "demonstration_diagram.dot",
    ),
    "learn": (MODEL, "state_activations.png", "reproduction_diagram.svg", "reproduction_diagram.dot"),
    "reproduce": (
        "reproduction.html", "reproduction.npz", "metrics.json", "fig8_reproduction.png",
        "fig10_reproduction.png", "fig11_strokes.png",
    ),
}  # fmt: skip
# Sub-folders of extra reproductions (``start_offset``, ``start_offset_<i>``).
REPRODUCTION_FOLDERS = "start_offset*"
# Sub-folder of the full demo's placements run (pipeline.placement_demo): a run of its own,
# made from this folder's scenario, removed with the folder's demonstrations.
PLACEMENTS_FOLDER = "placements"


def file_hash(path):
    """SHA-256 of a file's bytes, as hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


class RunFolder:
    """A run folder and its manifest.

    Parameters
    ----------
    path : path-like
    create : bool
        Create the folder if missing; otherwise a missing folder is a FileNotFoundError.
    """

    def __init__(self, path, *, create=False):
        self.path = Path(path)
        if self.path.exists() and not self.path.is_dir():
            raise ValueError(f"{self.path}: is a file, not a run folder")
        if create:
            self.path.mkdir(parents=True, exist_ok=True)
        elif not self.path.is_dir():
            raise FileNotFoundError(f"run folder not found: {self.path}")

    def __truediv__(self, name):
        return self.path / name

    @property
    def dataset(self):
        return self.path / DATASET

    @property
    def model(self):
        return self.path / MODEL

    def manifest(self):
        """The manifest's entries by stage ({} for a folder without one)."""
        path = self.path / MANIFEST
        if not path.is_file():
            return {}
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            raise ValueError(f"{path}: not a readable manifest; remove it and run again") from None
        return data if isinstance(data, dict) else {}

    def _write_manifest(self, entries):
        write_text_atomic(self.path / MANIFEST, json.dumps(entries, indent=2, sort_keys=True) + "\n")

    def clean_temporaries(self):
        """Remove temporary files left by interrupted atomic writes; return their names."""
        stale = sorted(self.path.glob(".*.tmp"))
        for sub in self.path.glob(REPRODUCTION_FOLDERS):
            stale += sorted(sub.glob(".*.tmp"))
        for path in stale:
            path.unlink(missing_ok=True)
        return [p.name for p in stale]

    def begin(self, stage):
        """Start ``stage``: remove its outputs and those of the later stages, and their
        manifest entries. Returns the names of the files removed."""
        later = STAGES[STAGES.index(stage) :]
        self.clean_temporaries()
        removed = []
        placements = self.path / PLACEMENTS_FOLDER
        if stage == "demonstrate" and placements.is_dir():
            removed += [f"{PLACEMENTS_FOLDER}/{p.relative_to(placements)}"
                        for p in sorted(placements.rglob("*")) if p.is_file()]  # fmt: skip
            shutil.rmtree(placements)
        for name in later:
            for pattern in OUTPUTS[name]:
                for path in self.path.glob(pattern):
                    path.unlink()
                    removed.append(path.name)
        # The extra reproductions (start offsets) were made from the model: they go when the
        # model or its data do, not when the main reproduction is run again.
        if "learn" in later:
            for sub in self.path.glob(REPRODUCTION_FOLDERS):
                if sub.is_dir():
                    removed += [f"{sub.name}/{n}" for n in RunFolder(sub).begin("reproduce")]
                    (sub / MANIFEST).unlink(missing_ok=True)
        entries = self.manifest()
        if any(name in entries for name in later):
            self._write_manifest({k: v for k, v in entries.items() if k not in later})
        return removed

    @contextlib.contextmanager
    def stage(self, stage):
        """``begin(stage)``, then run the block; if it fails or is interrupted, remove what
        the stage had written so far, so no partial output stays behind. Yields the names
        removed by ``begin``. The block calls :meth:`finish` when its files are written."""
        removed = self.begin(stage)
        try:
            yield removed
        except BaseException:
            with contextlib.suppress(OSError, ValueError):
                self.begin(stage)
            raise

    def finish(self, stage, written, *, inputs=()):
        """Record ``stage`` as done: the hashes of the files it wrote and read (paths)."""
        entries = self.manifest()
        entries[stage] = {
            "files": {self._name(p): file_hash(p) for p in written},
            "inputs": {self._name(p): file_hash(p) for p in inputs},
        }
        self._write_manifest(entries)

    def _name(self, path):
        path = Path(path)
        try:
            return str(path.resolve().relative_to(self.path.resolve()))
        except ValueError:
            return str(path.resolve())

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
                f"(an older or interrupted run): run {run_hint}"
            )
        if file_hash(path) != entry["files"][name]:
            raise ValueError(
                f"{path}: changed since '{stage}' wrote it (its hash differs from the "
                f"manifest's): run {run_hint}"
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
