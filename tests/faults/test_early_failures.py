"""A command that fails early (a bad --set, a missing input, a place it cannot write) or
partway leaves no folder it made: no empty --out folder, nor the folders above it that it
would have made (issue 25)."""

import os
import shutil

import pytest

from tooling.faults import SMALL, mount_tmpfs, run


@pytest.fixture
def root(tmp_path, base):
    root = tmp_path / "root"
    shutil.copytree(base, root, symlinks=True)
    return root


@pytest.fixture
def read_only(tmp_path):
    """A folder nothing can be written into: a read-only tmpfs as root, else mode 0555."""
    folder = tmp_path / "read_only"
    folder.mkdir()
    if os.geteuid() != 0:
        folder.chmod(0o555)
        yield folder
        folder.chmod(0o755)
        return
    with mount_tmpfs(folder, "ro,size=64k"):
        yield folder


BAD_SET = ["--set", "plant.contact_model=hydroelastc"]
# (name, argv with OUT for the new folder): each fails before anything is written.
EARLY = [
    ("demonstrate bad --set", ["demonstrate", "cotter_pin", "--out", "OUT", *BAD_SET]),
    ("demonstrate missing scenario", ["demonstrate", "missing.yaml", "--out", "OUT"]),
    ("demonstrate out of reach", ["demonstrate", "cotter_pin", "--out", "OUT", "--no-replay",
                                  "--set", "scene.position=[3,3,3]"]),  # fmt: skip
    ("reproduce bad --set", ["reproduce", "run", "--out", "OUT",
                             "--set", "reproduction.horizon=-1"]),  # fmt: skip
    ("reproduce no model", ["reproduce", "live", "--out", "OUT"]),
    ("import missing file", ["import", "missing.hdf5", "--out", "OUT"]),
    ("import not hdf5", ["import", "run/dataset.npz", "--out", "OUT"]),
    ("teleop missing log", ["teleop", "cotter_pin", "--out", "OUT", "--replay-inputs", "no.npz"]),
    ("teleop bad --set", ["teleop", "cotter_pin", "--out", "OUT", "--replay-inputs",
                          "live/inputs_1.npz", "--set", "emg.k_max=-3"]),  # fmt: skip
    ("teleop log of another task", ["teleop", "drawing", "--out", "OUT", "--no-replay",
                                    "--replay-inputs", "live/inputs_1.npz"]),  # fmt: skip
    ("demo bad --set", ["demo", "--out", "OUT", *BAD_SET]),
    ("sweep missing file", ["sweep", "missing.yaml", "--out", "OUT"]),
    ("export lerobot missing run", ["export", "missing", "OUT", "--format", "lerobot"]),
    ("emg-figure missing input", ["emg-figure", "missing.csv", "-o", "OUT/fig6.png"]),
    ("emg-figure bad windows", ["emg-figure", "-o", "OUT/fig6.png", "--windows", "100000",
                                "--duration", "0.1"]),  # fmt: skip
    ("stability bad delay", ["stability", "cotter_pin", "--delays", "0.5", "-o", "OUT/s.png"]),
]  # fmt: skip


@pytest.fixture
def fails(run_cli, root, monkeypatch):
    """``fails(argv)``: stderr of ``hemg-drake argv`` run in ``root``, which must exit 2 in one
    line."""
    monkeypatch.chdir(root)

    def run(argv):
        status, _, err = run_cli(argv)
        assert status == 2 and err.count("\n") == 1 and "Traceback" not in err, err[-1000:]
        return err

    return run


@pytest.mark.parametrize("argv", [argv for _, argv in EARLY], ids=[name for name, _ in EARLY])
def test_an_early_failure_leaves_no_folder_it_made(root, fails, argv):
    before = sorted(p.name for p in root.iterdir())
    fails([a.replace("OUT", "new/deeper") for a in argv])
    assert sorted(p.name for p in root.iterdir()) == before  # no new/, no new/deeper/


@pytest.mark.parametrize(
    "argv",
    [["demonstrate", "cotter_pin", "--out", "OUT", "--no-replay", *SMALL],
     ["reproduce", "run", "--out", "OUT", "--no-replay"],
     ["import", "demos.hdf5", "--out", "OUT"],
     ["teleop", "cotter_pin", "--out", "OUT", "--no-replay",
      "--replay-inputs", "live/inputs_1.npz"],
     ["export", "run", "OUT", "--format", "lerobot"],
     ["export", "run", "OUT/demos.hdf5"],
     ["demo", "--out", "OUT", "--tasks", "cotter_pin", "--no-replay", "--no-placements", *SMALL],
     ["emg-figure", "-o", "OUT/fig6.png"]],
    ids=lambda argv: argv[0] + ("-lerobot" if "lerobot" in argv else ""),
)  # fmt: skip
def test_a_place_it_cannot_write_is_refused_before_anything(fails, read_only, argv):
    assert str(read_only) in fails([a.replace("OUT", str(read_only / "new")) for a in argv])
    assert not os.listdir(read_only)


def test_a_failure_partway_in_a_new_folder_leaves_no_folder(root):
    # The folders are made when the stage starts writing; writing its dataset fails (an
    # injected I/O error at the third fault point).
    argv = ["demonstrate", "cotter_pin", "--out", "new/deeper", "--no-replay", *SMALL,
            "--set", "duration=0.6"]  # fmt: skip
    before = sorted(p.name for p in root.iterdir())
    done = run(argv, cwd=root, check=False, env={"HEMG_DRAKE_FAULT_AT": "3",
                                                  "HEMG_DRAKE_FAULT_ERRNO": "5"})  # fmt: skip
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr[-1000:]
    assert sorted(p.name for p in root.iterdir()) == before
