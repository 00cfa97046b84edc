"""export onto a full disk (a 200 kB tmpfs): one line naming the output, a non-zero exit,
nothing partial left, the previous export untouched; and an I/O error likewise."""

import errno
import subprocess
import sys

import numpy as np
import pytest

from hemg_drake.learning.demos import save_dataset

pytest.importorskip("h5py")
pytest.importorskip("pyarrow")


@pytest.fixture
def full_disk(tmp_path):
    """A 200 kB tmpfs, mounted for the test (skipped where mount is not allowed)."""
    from tooling.faults import mount_tmpfs

    with mount_tmpfs(tmp_path / "small", "size=200k") as mount_point:
        yield mount_point


@pytest.fixture
def dataset(tmp_path, make_demo):
    """A dataset of random demonstrations several times the tmpfs's size in either format."""
    path = tmp_path / "dataset.npz"
    save_dataset(path, [make_demo(c, 3000) for c in range(4)], {"task": "cotter_pin"})
    return path


def _export(dataset, fmt, output):
    command = [sys.executable, "-m", "hemg_drake.cli", "export", str(dataset), "--format", fmt,
               str(output)]  # fmt: skip
    return subprocess.run(command, capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("fmt, name", [("robomimic", "demos.hdf5"), ("lerobot", "demos")])
def test_full_disk_gives_one_line_and_leaves_nothing(full_disk, dataset, fmt, name):
    keep = full_disk / "keep.txt"
    keep.write_text("the user's file")
    result = _export(dataset, fmt, full_disk / name)
    assert result.returncode == 2, result.stderr[-500:]
    assert result.stderr.count("\n") == 1, result.stderr[-2000:]
    assert result.stderr == (f"hemg-drake export: error: {full_disk / name}: cannot write it: "
                             f"No space left on device; nothing was written\n")  # fmt: skip
    assert sorted(p.name for p in full_disk.iterdir()) == ["keep.txt"]  # no temporary left
    assert keep.read_text() == "the user's file"


@pytest.mark.parametrize("fmt, name", [("robomimic", "demos.hdf5"), ("lerobot", "demos")])
def test_full_disk_keeps_the_previous_export(full_disk, tmp_path, make_demo, dataset, fmt, name):
    small = tmp_path / "small.npz"
    save_dataset(small, [make_demo(0, 20)], {"task": "cotter_pin"})
    assert _export(small, fmt, full_disk / name).returncode == 0
    before = {p: p.read_bytes() for p in full_disk.rglob("*") if p.is_file()}
    result = _export(dataset, fmt, full_disk / name)
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr[-500:]
    assert {p: p.read_bytes() for p in full_disk.rglob("*") if p.is_file()} == before
    assert sorted(p.name for p in full_disk.iterdir()) == [name]


def test_an_io_error_names_the_output(tmp_path, make_demo, monkeypatch):
    from hemg_drake.learning import export

    def broken(path, data):
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(export, "write_bytes_atomic", broken)
    with pytest.raises(OSError) as error:
        export.export_robomimic(tmp_path / "d.hdf5", [make_demo(0, 10)])
    assert (error.value.errno, error.value.filename) == (errno.EIO, str(tmp_path / "d.hdf5"))
    assert "Input/output error" in str(error.value)
    assert not list(tmp_path.iterdir())
    # pyarrow's own messages carry no errno: the text is recognised.
    message = export.write_error("out", OSError("IOError: [Errno 28] No space left on device"))
    assert message.errno == errno.ENOSPC and message.filename == "out"
    assert np.isscalar(message.errno)
