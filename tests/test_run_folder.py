"""Run folders: the provenance manifest, stages that build the folder's next version beside
it and swap it in whole, the files they keep and replace, one writer at a time, repair, and
checks that refuse files of another run naming the command to run."""

import hashlib
import json
import os
import subprocess
import sys

import pytest

from hemg_drake import folder_versions, run_folder
from hemg_drake.fileio import write_text_atomic
from hemg_drake.folder_lock import FolderBusy, folder_lock
from hemg_drake.run_folder import MANIFEST, RunFolder, repair

DEMONSTRATE_FILES = ["dataset.npz", "replay_1.html", "replay_2.html", "demonstrations.png",
                     "fig6_emg.png"]  # fmt: skip
# The diagrams depend on the model: the learn stage's.
LEARN_FILES = ["model.npz", "state_activations.png", "reproduction_diagram.dot",
               "demonstration_diagram.svg"]  # fmt: skip
REPRODUCE_FILES = ["reproduction.html", "reproduction.npz", "metrics.json", "fig8_reproduction.png",
                   "fig11_strokes.png"]  # fmt: skip
EXTRA_FILES = ["start_offset/metrics.json", "start_offset/reproduction.npz"]
# A reproduction a person asked for in a sub-folder (reproduce --out runs/x/lqr).
LQR_FILES = ["lqr/metrics.json", "lqr/reproduction.npz"]
# A user's own files in the folder: no stage owns them.
OWN_FILES = ["notes.txt", "my_recording.csv", "mine/analysis.py"]
HINT = "hemg-drake demonstrate SCENARIO --out runs/x"
STAGES = ["demonstrate", "learn", "reproduce"]


def sha256(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def touch(folder, names, text="contents of {}\n"):
    """Write each file as the stages do: whole, to a new file renamed into place."""
    for name in names:
        write_text_atomic(folder / name, text.format(name))
    return [folder / name for name in names]


def snapshot(path):
    """Every file under ``path`` (and beside it: staging folders) by name, with its bytes."""
    files = {str(p.relative_to(path)): p.read_bytes() for p in path.rglob("*") if p.is_file()}
    siblings = sorted(p.name for p in path.parent.iterdir() if p.name.startswith(f".{path.name}."))
    return files, siblings


@pytest.fixture
def full(tmp_path):
    """A folder holding every stage's outputs (and a user's files), all three finished."""
    folder = RunFolder(tmp_path / "run", create=True)
    folder.finish("demonstrate", touch(folder.path, DEMONSTRATE_FILES))
    folder.finish("learn", touch(folder.path, LEARN_FILES), inputs=[folder.dataset])
    reproduced = touch(folder.path, REPRODUCE_FILES)
    folder.finish("reproduce", reproduced, inputs=[folder.model, folder.dataset])
    for names in (EXTRA_FILES, LQR_FILES):
        written = touch(folder.path, names)
        sub = RunFolder(folder.path / names[0].split("/")[0])
        sub.finish("reproduce", written, inputs=[folder.model, folder.dataset])
    touch(folder.path, OWN_FILES)
    return folder


def names(folder):
    return sorted(str(p.relative_to(folder.path)) for p in folder.path.rglob("*") if p.is_file())


def test_folder_arguments(tmp_path):
    assert RunFolder(tmp_path / "a" / "b", create=True).path.is_dir()
    with pytest.raises(FileNotFoundError, match="run folder not found"):
        RunFolder(tmp_path / "nowhere")
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match="is a file, not a run folder"):
        RunFolder(tmp_path / "file", create=True)
    with pytest.raises(ValueError, match="is a file, not a run folder"):
        RunFolder.output(tmp_path / "file")


def test_manifest_records_the_hashes_of_what_each_stage_wrote_and_read(full):
    assert RunFolder(full.path.parent / "fresh", create=True).manifest() == {}
    entries = json.loads((full.path / MANIFEST).read_text())
    assert entries == full.manifest()
    assert set(entries) == {"demonstrate", "learn", "reproduce"}
    assert entries["demonstrate"]["files"] == {
        name: sha256(full.path / name) for name in DEMONSTRATE_FILES
    }
    assert entries["demonstrate"]["inputs"] == {}
    assert entries["learn"]["files"] == {name: sha256(full.path / name) for name in LEARN_FILES}
    assert entries["learn"]["inputs"] == {"dataset.npz": sha256(full.dataset)}
    assert entries["reproduce"]["inputs"] == {
        "model.npz": sha256(full.model), "dataset.npz": sha256(full.dataset)
    }  # fmt: skip
    # The reproduction in the sub-folder names the model it came from by path.
    sub = RunFolder(full.path / "start_offset").manifest()["reproduce"]
    assert sub["inputs"] == {"../model.npz": sha256(full.model),
                             "../dataset.npz": sha256(full.dataset)}  # fmt: skip


def test_unreadable_manifest_is_a_clear_error_that_keeps_the_files(tmp_path):
    folder = RunFolder(tmp_path, create=True)
    (tmp_path / MANIFEST).write_text("{not json")
    with pytest.raises(ValueError) as error:
        folder.manifest()
    message = str(error.value)
    assert "manifest.json: not a readable manifest; hemg-drake repair" in message
    assert "remove" not in message and "\n" not in message


def run_stage(folder, stage, new_files, *, fail=None, keep_own=False):
    """A stage writing ``new_files`` (text naming the stage) through a transaction."""
    with RunFolder.output(folder.path).transaction(stage, keep_own=keep_own) as new:
        written = touch(new.path, new_files, text=f"{stage} again: {{}}\n")
        if fail is not None:
            raise fail
        inputs = {"learn": [new.dataset], "reproduce": [new.model, new.dataset]}.get(stage, [])
        new.finish(stage, written, inputs=[p for p in inputs if p.exists()])
    return new


@pytest.mark.parametrize(
    "stage, kept, extras_kept",
    [
        ("demonstrate", [], False),
        ("learn", DEMONSTRATE_FILES, False),
        ("reproduce", DEMONSTRATE_FILES + LEARN_FILES, True),
    ],
)
def test_a_stage_replaces_its_outputs_and_the_later_ones_and_keeps_the_rest(
    full, stage, kept, extras_kept
):  # fmt: skip
    before = {name: (full / name).stat().st_ino for name in names(full)}
    outputs = {"demonstrate": DEMONSTRATE_FILES[:2], "learn": LEARN_FILES[:1],
               "reproduce": REPRODUCE_FILES[:2]}[stage]  # fmt: skip
    new = run_stage(full, stage, outputs)
    assert new.removed  # what it replaced, for the message
    # Exactly the stage's and the later stages' files go; the reproductions in sub-folders
    # (made from the model and dataset) go with them, not when the main reproduction runs
    # again; earlier stages' files, the user's own files (and folders) stay.
    sub_files = [*EXTRA_FILES, *LQR_FILES, "start_offset/manifest.json", "lqr/manifest.json"]
    expected = [*kept, *(sub_files if extras_kept else []), *OWN_FILES, *outputs, MANIFEST]
    assert names(full) == sorted(set(expected))
    # What stays is the very file (a hard link), not a copy.
    for name in set(kept) | set(OWN_FILES):
        assert (full / name).stat().st_ino == before[name]
    assert (full / outputs[0]).read_text() == f"{stage} again: {outputs[0]}\n"
    assert sorted(full.manifest()) == STAGES[: STAGES.index(stage) + 1]
    for name in kept:
        full.check(STAGES[0] if name in DEMONSTRATE_FILES else "learn", full / name, run_hint=HINT)
    # Nothing is left beside the folder.
    assert snapshot(full.path)[1] == []


@pytest.mark.parametrize("interruption", [RuntimeError("simulation failed"), KeyboardInterrupt()])
@pytest.mark.parametrize("stage", STAGES)
def test_a_failed_stage_leaves_the_folder_exactly_as_it_was(full, stage, interruption):
    before = snapshot(full.path)
    with pytest.raises(type(interruption)):
        run_stage(full, stage, ["dataset.npz", "model.npz", "metrics.json"], fail=interruption)
    assert snapshot(full.path) == before


def test_a_stage_writing_into_a_kept_file_in_place_is_caught(full):
    # Kept files are hard links to the previous version's: a stage must write whole new
    # files (fileio's atomic writers), never into one it kept.
    with pytest.raises(RuntimeError, match="wrote into a file it kept"):
        with RunFolder.output(full.path).transaction("learn") as new:
            with open(new / "notes.txt", "a") as f:
                f.write("more\n")
            new.finish("learn", [new / "notes.txt"])


def test_a_stage_that_records_nothing_changes_nothing(full):
    before = snapshot(full.path)
    with pytest.raises(RuntimeError, match="did not record its files"):
        with RunFolder.output(full.path).transaction("learn") as new:
            touch(new.path, ["model.npz"])
    assert snapshot(full.path) == before


def test_a_new_folder_is_made_and_unmade_on_failure(tmp_path):
    target = tmp_path / "a" / "b" / "run"
    with pytest.raises(RuntimeError):
        run_stage(RunFolder.output(target), "demonstrate", ["dataset.npz"], fail=RuntimeError())
    assert list(tmp_path.iterdir()) == []  # no empty --out folders left behind
    new = run_stage(RunFolder.output(target), "demonstrate", ["dataset.npz"])
    assert names(RunFolder(target)) == ["dataset.npz", MANIFEST]
    assert new.shown(new.dataset) == target.resolve() / "dataset.npz"


def test_a_folder_the_tool_did_not_make_is_refused_untouched(tmp_path):
    # As issue 25 found: a person's folder with files whose names the stages use.
    mine = touch(tmp_path / "mine", ["metrics.json", "replay_1.html", "placements/x.txt",
                                     "start_offset/reproduction.npz", "notes.txt"])  # fmt: skip
    before = snapshot(tmp_path / "mine")
    for stage in STAGES:
        with pytest.raises(ValueError) as error:
            run_stage(RunFolder.output(tmp_path / "mine"), stage, ["dataset.npz"])
        assert "holds files hemg-drake did not write (no manifest.json)" in str(error.value)
    assert snapshot(tmp_path / "mine") == before and all(p.exists() for p in mine)
    # An empty folder is fine.
    (tmp_path / "empty").mkdir()
    run_stage(RunFolder.output(tmp_path / "empty"), "demonstrate", ["dataset.npz"])


def test_a_file_a_stage_would_write_that_no_stage_recorded_is_refused(full):
    (full / "metrics.json").unlink()
    others = [full / n for n in REPRODUCE_FILES if n != "metrics.json"]
    full.finish("reproduce", others, inputs=[full.model])
    (full / "metrics.json").write_text("my own metrics\n")
    before = snapshot(full.path)
    with pytest.raises(ValueError, match=r"metrics.json: not written by hemg-drake .* move it"):
        run_stage(full, "learn", ["model.npz"])
    assert snapshot(full.path) == before


def test_a_persons_takes_are_kept_by_a_take_and_refused_by_demonstrate(full):
    full.finish("demonstrate", [full / n for n in DEMONSTRATE_FILES], command="teleop")
    run_stage(full, "demonstrate", ["replay_3.html"], keep_own=True)  # one more take
    assert set(DEMONSTRATE_FILES) < set(names(full)) and "model.npz" not in names(full)
    # A take rewrites the dataset: what was made from it goes.
    assert not (full / "start_offset").exists() and not (full / "lqr").exists()
    takes = [full / n for n in [*DEMONSTRATE_FILES, "replay_3.html"]]
    full.finish("demonstrate", takes, command="teleop")
    before = snapshot(full.path)
    with pytest.raises(ValueError, match="holds takes a person recorded"):
        run_stage(full, "demonstrate", ["dataset.npz"])
    assert snapshot(full.path) == before


def test_a_reproduction_elsewhere_is_not_touched(full, tmp_path):
    elsewhere = run_stage(RunFolder.output(tmp_path / "lqr"), "reproduce", ["metrics.json"])
    before = snapshot(elsewhere.final)
    run_stage(full, "demonstrate", ["dataset.npz"])
    assert snapshot(elsewhere.final) == before


def hold_lock(path, mode="exclusive"):
    """A child process that holds a lock on ``path`` until its stdin closes."""
    code = (
        "import sys; from hemg_drake.folder_lock import folder_lock\n"
        f"with folder_lock(sys.argv[1], shared={mode == 'shared'}):\n"
        "    print('locked', flush=True); sys.stdin.read()\n"
    )
    child = subprocess.Popen([sys.executable, "-c", code, str(path)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)  # fmt: skip
    assert child.stdout.readline() == "locked\n"
    return child


def test_a_second_writer_is_refused_naming_the_first(full):
    before = snapshot(full.path)
    child = hold_lock(full.path)
    try:
        for stage in STAGES:
            with pytest.raises(FolderBusy) as error:
                run_stage(full, stage, ["dataset.npz"])
            assert f"PID {child.pid}" in str(error.value) and "\n" not in str(error.value)
        assert snapshot(full.path) == before
    finally:
        child.communicate("")
    run_stage(full, "reproduce", ["metrics.json"])  # free again once it has exited


def test_readers_share_and_a_writer_waits_for_none(full):
    child = hold_lock(full.path, "shared")
    try:
        with folder_lock(full.path, shared=True):
            pass
        with pytest.raises(FolderBusy, match="is using it"):
            run_stage(full, "learn", ["model.npz"])
    finally:
        child.communicate("")


def test_the_lock_follows_the_folder_through_the_swap(full):
    # Held for a whole command that runs two stages: the second finds it held.
    with folder_lock(full.path) as lock:
        first = lock.fd
        run_stage(full, "learn", ["model.npz"])
        assert lock.fd != first  # now on the new version of the folder
        assert os.path.samestat(os.fstat(lock.fd), os.stat(full.path))
        child = subprocess.run(
            [sys.executable, "-c", "import sys; from hemg_drake.folder_lock import folder_lock\n"
             "with folder_lock(sys.argv[1]): pass", str(full.path)],
            capture_output=True, text=True,
        )  # fmt: skip
        assert child.returncode != 0 and "FolderBusy" in child.stderr
        run_stage(full, "reproduce", ["metrics.json"])


def test_what_a_killed_stage_left_beside_is_tidied_by_the_next(full):
    target = full.path
    building = target.parent / f".{target.name}.{run_folder.NEW}-99999"
    touch(building, ["dataset.npz", "replay_1.html"])
    # A replaced version whose removal was cut short, holding a file a person added while
    # the stage ran: it is moved into the folder, not lost.
    old = target.parent / f".{target.name}.{run_folder.OLD}-99998"
    touch(old, ["notes.txt", "added_meanwhile.txt"])
    (old / MANIFEST).write_text("{}")
    run_stage(full, "reproduce", ["metrics.json"])
    assert not building.exists() and not old.exists()
    assert (full / "added_meanwhile.txt").read_text() == "contents of added_meanwhile.txt\n"
    assert (full / "notes.txt").read_text() == "contents of notes.txt\n"


def test_the_two_rename_fallback_and_its_recovery(full, monkeypatch):
    monkeypatch.setattr(folder_versions, "_renameat2", lambda: None)
    run_stage(full, "reproduce", ["metrics.json"])
    assert (full / "metrics.json").read_text() == "reproduce again: metrics.json\n"
    # A crash between its two renames: the folder is missing and its last version is
    # beside it. The next stage puts it back first.
    aside = full.path.parent / f".{full.path.name}.{run_folder.OLD}-424242"
    os.rename(full.path, aside)
    before = snapshot(aside)[0]
    run_folder.recover(full.path)
    assert snapshot(full.path)[0] == before


def test_repair_records_the_files_there_and_changes_nothing_else(full):
    (full / MANIFEST).unlink()
    touch(full.path, ["inputs_1.npz"])
    before = {n: (full / n).read_bytes() for n in names(full)}
    recorded = repair(full.path)
    assert recorded["demonstrate"] == sorted([*DEMONSTRATE_FILES, "inputs_1.npz"])
    assert recorded["learn"] == sorted(LEARN_FILES)
    assert {n: (full / n).read_bytes() for n in names(full) if n != MANIFEST} == before
    entries = full.manifest()
    assert entries["demonstrate"]["command"] == "teleop"  # the takes are a person's
    full.check("demonstrate", full.dataset, run_hint=HINT)
    # The model is the tool's again (learn may replace it) but claims no dataset.
    with pytest.raises(ValueError, match="was not made from this folder's dataset.npz"):
        full.check_made_from("learn", full.dataset, run_hint="hemg-drake learn runs/x")


def test_repair_keeps_entries_that_still_hold_and_refuses_a_folder_without_a_dataset(full, tmp_path):
    entries = full.manifest()
    (full / "metrics.json").write_text("edited\n")
    repair(full.path)
    repaired = full.manifest()
    assert repaired["demonstrate"] == entries["demonstrate"]
    assert repaired["learn"] == entries["learn"]
    assert repaired["reproduce"]["repaired"] and repaired["reproduce"]["inputs"] == {}
    touch(tmp_path / "other", ["notes.txt"])
    with pytest.raises(ValueError, match="no dataset.npz to record; nothing to repair"):
        repair(tmp_path / "other")
    assert names(RunFolder(tmp_path / "other")) == ["notes.txt"]


def test_check_accepts_the_recorded_file(full):
    entry = full.check("demonstrate", full.dataset, run_hint=HINT)
    assert entry["files"]["dataset.npz"] == sha256(full.dataset)
    full.check_made_from("learn", full.dataset, run_hint="hemg-drake learn runs/x")


def test_check_refuses_a_changed_file_naming_the_commands(full):
    full.dataset.write_text("another run's dataset\n")
    with pytest.raises(ValueError) as error:
        full.check("demonstrate", full.dataset, run_hint=HINT)
    message = str(error.value)
    assert "dataset.npz: changed since 'demonstrate' wrote it" in message
    assert f"hemg-drake repair {full.path}" in message
    assert message.endswith(f"run {HINT}") and "\n" not in message


def test_check_refuses_a_file_no_finished_stage_wrote(full, tmp_path):
    with pytest.raises(ValueError, match=r"model.npz: no finished 'demonstrate' recorded it"):
        full.check("demonstrate", full.model, run_hint=HINT)
    bare = RunFolder(tmp_path / "bare", create=True)
    touch(bare.path, ["dataset.npz"])
    with pytest.raises(ValueError) as error:
        bare.check("demonstrate", bare.dataset, run_hint=HINT)
    message = str(error.value)
    assert "no finished 'demonstrate' recorded it" in message and "interrupted" in message
    assert "hemg-drake repair" in message  # advice that keeps the files first


def test_check_made_from_refuses_a_model_of_another_dataset(full):
    full.dataset.write_text("a new dataset\n")
    full.finish("demonstrate", [full.dataset])
    with pytest.raises(ValueError) as error:
        full.check_made_from("learn", full.dataset, run_hint="hemg-drake learn runs/x")
    message = str(error.value)
    assert message.startswith(f"{full.model}: was not made from this folder's dataset.npz")
    assert message.endswith("run hemg-drake learn runs/x")


def test_a_stage_is_refused_from_inside_the_folder(full, monkeypatch):
    # The swap would leave the shell in a deleted folder.
    before = snapshot(full.path)
    for where in (full.path, full.path / "mine"):
        monkeypatch.chdir(where)
        with pytest.raises(ValueError, match="is the folder this command runs in"):
            run_stage(RunFolder.output("."), "reproduce", ["metrics.json"])
    assert snapshot(full.path) == before
