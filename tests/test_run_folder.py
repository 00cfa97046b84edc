"""Run folders: the provenance manifest, stages that clear what they replace, stale
temporaries, and checks that refuse files of another run naming the command to run."""

import hashlib
import json

import pytest

from hemg_drake.run_folder import MANIFEST, RunFolder

DEMONSTRATE_FILES = ["dataset.npz", "replay_1.html", "replay_2.html", "demonstrations.png",
                     "fig6_emg.png", "demonstration_diagram.svg"]  # fmt: skip
# The reproduction diagram's picture depends on the model: the learn stage's to remove.
LEARN_FILES = ["model.npz", "state_activations.png", "reproduction_diagram.dot"]
REPRODUCE_FILES = ["reproduction.html", "reproduction.npz", "metrics.json", "fig8_reproduction.png",
                   "fig11_strokes.png"]  # fmt: skip
EXTRA_FILES = ["start_offset/metrics.json", "start_offset/reproduction.npz"]
# A user's own files in the folder: no stage owns them.
OWN_FILES = ["notes.txt", "my_recording.csv"]
HINT = "hemg-drake demonstrate SCENARIO --out runs/x"


def sha256(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def touch(folder, names):
    for name in names:
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(f"contents of {name}\n")
    return [folder / name for name in names]


@pytest.fixture
def full(tmp_path):
    """A folder holding every stage's outputs (and a user's files), all three finished."""
    folder = RunFolder(tmp_path / "run", create=True)
    demonstrated = touch(folder.path, DEMONSTRATE_FILES)
    folder.finish("demonstrate", demonstrated)
    learnt = touch(folder.path, LEARN_FILES)
    folder.finish("learn", learnt, inputs=[folder.dataset])
    reproduced = touch(folder.path, REPRODUCE_FILES)
    folder.finish("reproduce", reproduced, inputs=[folder.model, folder.dataset])
    extra = touch(folder.path, EXTRA_FILES)
    RunFolder(folder.path / "start_offset").finish("reproduce", extra, inputs=[folder.model])
    touch(folder.path, OWN_FILES)
    return folder


def names(folder):
    return sorted(
        str(p.relative_to(folder.path)) for p in folder.path.rglob("*") if p.is_file()
    )


def test_folder_arguments(tmp_path):
    assert RunFolder(tmp_path / "a" / "b", create=True).path.is_dir()
    with pytest.raises(FileNotFoundError, match="run folder not found"):
        RunFolder(tmp_path / "nowhere")
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match="is a file, not a run folder"):
        RunFolder(tmp_path / "file", create=True)


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
    assert list(sub["inputs"].values()) == [sha256(full.model)]
    assert list(sub["inputs"]) == [str(full.model.resolve())]


def test_unreadable_manifest_is_a_clear_error(tmp_path):
    folder = RunFolder(tmp_path, create=True)
    (tmp_path / MANIFEST).write_text("{not json")
    with pytest.raises(ValueError, match="manifest.json: not a readable manifest; remove it"):
        folder.manifest()


@pytest.mark.parametrize(
    "stage, kept",
    [
        ("demonstrate", []),
        ("learn", DEMONSTRATE_FILES),
        ("reproduce", DEMONSTRATE_FILES + LEARN_FILES),
    ],
)
def test_begin_removes_the_stages_outputs_and_the_later_ones(full, stage, kept):
    removed = full.begin(stage)
    # Exactly the stage's and the later stages' files go; the extra reproductions (made from
    # the model) go with the model, not when the main reproduction runs again; earlier
    # stages' files, the user's own files and the manifest stay.
    extra_kept = EXTRA_FILES + ["start_offset/manifest.json"] if stage == "reproduce" else []
    assert names(full) == sorted([*kept, *extra_kept, *OWN_FILES, MANIFEST])
    gone = set(DEMONSTRATE_FILES + LEARN_FILES + REPRODUCE_FILES) - set(kept)
    assert gone | (set() if extra_kept else set(EXTRA_FILES)) == set(removed)
    # Their manifest entries go with them; the earlier stages' stay as they were.
    stages = ["demonstrate", "learn", "reproduce"]
    earlier = stages[: stages.index(stage)]
    assert sorted(full.manifest()) == sorted(earlier)
    for name in kept:
        full.check(stages[0] if name in DEMONSTRATE_FILES else "learn", full / name, run_hint=HINT)


def test_begin_on_a_fresh_folder_removes_nothing(tmp_path):
    folder = RunFolder(tmp_path, create=True)
    touch(tmp_path, OWN_FILES)
    assert folder.begin("demonstrate") == []
    assert names(folder) == sorted(OWN_FILES)


def test_clean_temporaries_removes_what_interrupted_atomic_writes_left(full):
    # As tempfile.mkstemp(prefix=".NAME.", suffix=".tmp") leaves them on a SIGKILL.
    stale = touch(full.path, [".dataset.npz.abc123.tmp", ".replay_1.html.x9_z.tmp",
                              "start_offset/.metrics.json.q1.tmp"])  # fmt: skip
    keep = touch(full.path, ["keep.tmp", ".hidden_config"])
    removed = full.clean_temporaries()
    assert sorted(removed) == sorted(p.name for p in stale)
    assert not any(p.exists() for p in stale)
    assert all(p.exists() for p in keep)
    assert (full / "dataset.npz").exists()
    # begin cleans them too, whatever the stage.
    touch(full.path, [".model.npz.zz.tmp"])
    full.begin("reproduce")
    assert not (full / ".model.npz.zz.tmp").exists()


def test_check_accepts_the_recorded_file(full):
    entry = full.check("demonstrate", full.dataset, run_hint=HINT)
    assert entry["files"]["dataset.npz"] == sha256(full.dataset)
    full.check_made_from("learn", full.dataset, run_hint="hemg-drake learn runs/x")


def test_check_refuses_a_changed_file_naming_the_command(full):
    full.dataset.write_text("another run's dataset\n")
    with pytest.raises(ValueError) as error:
        full.check("demonstrate", full.dataset, run_hint=HINT)
    message = str(error.value)
    assert "dataset.npz: changed since 'demonstrate' wrote it" in message
    assert message.endswith(f"run {HINT}") and "\n" not in message


def test_check_refuses_a_file_no_finished_stage_wrote(full, tmp_path):
    # Not in the stage's record (a file of another stage, or of an older run) ...
    with pytest.raises(ValueError, match=r"model.npz: no finished 'demonstrate' recorded it"):
        full.check("demonstrate", full.model, run_hint=HINT)
    # ... or the stage has no record at all (never finished, or interrupted).
    bare = RunFolder(tmp_path / "bare", create=True)
    touch(bare.path, ["dataset.npz"])
    with pytest.raises(ValueError) as error:
        bare.check("demonstrate", bare.dataset, run_hint=HINT)
    message = str(error.value)
    assert "no finished 'demonstrate' recorded it" in message and "interrupted" in message
    assert message.endswith(f"run {HINT}")


def test_check_made_from_refuses_a_model_of_another_dataset(full):
    # A new dataset in the folder (the model was fitted on the one before).
    full.dataset.write_text("a new dataset\n")
    full.finish("demonstrate", [full.dataset])
    with pytest.raises(ValueError) as error:
        full.check_made_from("learn", full.dataset, run_hint="hemg-drake learn runs/x")
    message = str(error.value)
    assert message.startswith(f"{full.model}: was not made from this folder's dataset.npz")
    assert message.endswith("run hemg-drake learn runs/x")
    # A stage with no record was made from nothing here.
    full.begin("learn")
    with pytest.raises(ValueError, match="was not made from this folder's dataset.npz"):
        full.check_made_from("learn", full.dataset, run_hint="hemg-drake learn runs/x")


@pytest.mark.parametrize("interruption", [RuntimeError("simulation failed"), KeyboardInterrupt()])
def test_a_failed_stage_leaves_no_partial_output(full, interruption):
    with pytest.raises(type(interruption)):
        with full.stage("learn") as removed:
            assert "model.npz" in removed and not full.model.exists()
            touch(full.path, ["model.npz"])  # written, then the stage fails
            raise interruption
    assert not full.model.exists() and not (full / "state_activations.png").exists()
    assert sorted(full.manifest()) == ["demonstrate"]
    assert names(full) == sorted([*DEMONSTRATE_FILES, *OWN_FILES, MANIFEST])


def test_a_finished_stage_keeps_its_outputs(full):
    with full.stage("learn"):
        written = touch(full.path, LEARN_FILES)
        full.finish("learn", written, inputs=[full.dataset])
    full.check("learn", full.model, run_hint="hemg-drake learn runs/x")
    full.check_made_from("learn", full.dataset, run_hint="hemg-drake learn runs/x")
    assert sorted(full.manifest()) == ["demonstrate", "learn"]
