import numpy as np
import pytest

from hemg_drake.fileio import atomic_open, save_npz_atomic, write_text_atomic


def test_atomic_write_replaces_whole_file(tmp_path):
    path = tmp_path / "out.txt"
    write_text_atomic(path, "old")
    write_text_atomic(path, "new")
    assert path.read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_crash_midway_leaves_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "out.txt"
    write_text_atomic(path, "old")
    with pytest.raises(RuntimeError):
        with atomic_open(path) as f:
            f.write("half")
            raise RuntimeError("crash")
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_npz_round_trip(tmp_path):
    path = tmp_path / "a.npz"
    save_npz_atomic(path, x=np.arange(3.0))
    with np.load(path) as data:
        np.testing.assert_array_equal(data["x"], np.arange(3.0))


def test_file_mode_follows_the_umask(tmp_path):
    import os

    old = os.umask(0o022)
    try:
        write_text_atomic(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644


def test_load_npz_names_the_file_and_the_kind(tmp_path):
    from hemg_drake.fileio import load_npz

    with pytest.raises(FileNotFoundError, match="HSMM model file not found: .*none.npz"):
        load_npz(tmp_path / "none.npz", kind="HSMM model")
    write_text_atomic(tmp_path / "junk.npz", "not a zip archive")
    with pytest.raises(ValueError, match=r"junk.npz: not a readable NPZ file \(dataset expected\)"):
        load_npz(tmp_path / "junk.npz", kind="dataset")
    save_npz_atomic(tmp_path / "ok.npz", x=np.arange(2.0))
    np.testing.assert_array_equal(load_npz(tmp_path / "ok.npz", kind="dataset")["x"], [0.0, 1.0])
