"""A full disk at each moment a command writes (a small tmpfs, filled so that the space runs
out in a chosen file: a replay, the dataset, a figure, the manifest; or no inode left for the
new version's folder or its hard links): one line on stderr naming the file and the reason,
exit 2, no traceback, every folder exactly as it was and nothing left beside it; once there is
space the same command works and writes the run a roomy disk gets (issue 25).

Mounting needs root: skipped elsewhere; ``.ci/run`` (root) requires them to run.
"""

import os
import re
import shutil
from pathlib import Path

import pytest

from tooling.faults import SMALL, Case, leftovers, mount_tmpfs, run, snapshot

PAGE = 4096  # tmpfs allocates whole pages
NO_SPACE = "No space left on device"


class SmallDisk:
    """A tmpfs holding a copy of the base runs (``root``) and what fills it (``spare``)."""

    def __init__(self, mount):
        self.mount, self.root, self.spare = mount, mount / "root", mount / "spare"

    def holding(self, base):
        shutil.copytree(base, self.root, symlinks=True)
        self.spare.mkdir()
        return self.root

    def leave(self, *, pages=None, inodes=None):
        """Fill the disk until ``pages`` pages (and ``inodes`` inodes) are free."""
        if pages is not None:
            free = os.statvfs(self.mount).f_bavail
            assert free >= pages, (free, pages)
            with open(self.spare / "blocks", "wb") as f:
                f.write(b"\0" * ((free - pages) * PAGE))
            assert os.statvfs(self.mount).f_bavail == pages
        if inodes is not None:
            for index in range(os.statvfs(self.mount).f_favail - inodes):
                (self.spare / f"inode_{index}").touch()
            assert os.statvfs(self.mount).f_favail == inodes

    def release(self):
        shutil.rmtree(self.spare)
        self.spare.mkdir()


@pytest.fixture
def disk(tmp_path):
    """A 32 MB tmpfs with 3000 inodes, mounted for the test (skipped where mount is refused)."""
    with mount_tmpfs(tmp_path / "disk", "size=32m,nr_inodes=3000") as mount:
        yield SmallDisk(mount)


_CASES = {}


def case(name, base, tmp_path_factory):
    """The command's states before and after and its fault points, learnt once."""
    if name not in _CASES:
        _CASES[name] = Case(name, base, tmp_path_factory.mktemp(f"{name}-reference")).learn_states()
    return _CASES[name]


def writes(case):
    """(file name, free pages that let every earlier write of the command succeed and this
    one fail), in the order the command writes them."""
    sizes = {Path(rel).name: len(data) for rel, data in case.after.items()}
    held, found = {}, []
    for point in case.points:  # "3 write dataset.npz"
        _, what, name = (point.split(" ", 2) + ["", ""])[:3]
        if what == "write":
            pages = -(-sizes[name] // PAGE)
            found.append((name, sum(held.values()) + pages // 2))
            held[name] = pages  # the earlier file of that name is freed at the rename
    return found


def everything(root):
    """Every file with its bytes, and every folder (an empty one too), under ``root``."""
    folders = sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_dir())
    return snapshot(root), folders


def fails_in_one_line(done, command):
    assert done.returncode == 2, done.stderr[-2000:]
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr[-2000:]
    prefix = f"hemg-drake {command}: error: "
    assert done.stderr.startswith(prefix), done.stderr
    return done.stderr.removeprefix(prefix).rstrip("\n")


def check_full_disk(disk, case, *, pages=None, inodes=None):
    """Run ``case`` on a disk left with ``pages``/``inodes`` free: one line, all as it was;
    then with space: the new run. Returns the line's text after "error: "."""
    root = disk.holding(case.base)
    before = everything(root)
    disk.leave(pages=pages, inodes=inodes)
    done = run(case.argv, cwd=root, check=False)
    line = fails_in_one_line(done, case.name)
    assert everything(root) == before
    assert not leftovers(root / case.folder)
    disk.release()
    run(case.argv, cwd=root)  # with space, it works
    assert snapshot(root / case.folder) == case.after
    assert not leftovers(root / case.folder)
    return line


# (command, which of its writes runs out of space): the first, a middle one, the last.
# make test runs the worst place (the last write: the manifest) of learn and import, which
# share the writing with the others (fileio); the rest are .ci/run's deep step (make test
# keeps under 10 minutes).
DEEP = pytest.mark.deep
POINTS = [
    pytest.param("demonstrate", 0, marks=DEEP), pytest.param("demonstrate", 2, marks=DEEP),
    pytest.param("demonstrate", -1, marks=DEEP),
    pytest.param("learn", 1, marks=DEEP), ("learn", -1),
    pytest.param("reproduce", 0, marks=DEEP), pytest.param("reproduce", -1, marks=DEEP),
    pytest.param("teleop", 0, marks=DEEP), pytest.param("teleop", -1, marks=DEEP),
    pytest.param("import", 0, marks=DEEP), ("import", -1),
]  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("name, which", POINTS)
def test_a_full_disk_while_writing_names_the_file_and_keeps_the_run(
    disk, base, tmp_path_factory, name, which
):  # fmt: skip
    the_case = case(name, base, tmp_path_factory)
    file, pages = writes(the_case)[which]
    line = check_full_disk(disk, the_case, pages=pages)
    target = os.path.realpath(disk.root / the_case.folder)
    assert line == f"{target}/{file}: {NO_SPACE}; nothing in {target}/ was changed"


@pytest.mark.slow
@pytest.mark.parametrize("name, inodes", [pytest.param("demonstrate", 0, marks=DEEP),
                                          ("learn", 0), pytest.param("learn", 2, marks=DEEP)])
def test_no_inode_for_the_new_version_or_its_links_names_the_folder(
    disk, base, tmp_path_factory, name, inodes
):  # fmt: skip
    # 0: the new version's folder cannot be made; 2: it and one hard link can, the next not.
    the_case = case(name, base, tmp_path_factory)
    line = check_full_disk(disk, the_case, inodes=inodes)
    target = os.path.realpath(disk.root / the_case.folder)
    suffix = f": {NO_SPACE}; nothing in {target}/ was changed"
    if inodes == 0:
        assert line == target + suffix
    else:
        named = re.fullmatch(re.escape(target) + r"/([^/]+)" + re.escape(suffix), line)
        assert named and named[1] in the_case.before, line


@pytest.mark.slow
def test_repair_on_a_full_disk_keeps_the_folder(disk, base):
    root = disk.holding(base)
    (root / "run" / "manifest.json").unlink()
    before = everything(root)
    disk.leave(pages=0)
    done = run(["repair", "run"], cwd=root, check=False)
    assert fails_in_one_line(done, "repair") == f"run/manifest.json: {NO_SPACE}"  # as given
    assert everything(root) == before
    disk.release()
    run(["repair", "run"], cwd=root)
    assert (root / "run" / "manifest.json").is_file()


@pytest.mark.slow
@pytest.mark.deep
def test_demo_on_a_full_disk_stops_in_one_line_between_whole_stages(disk):
    # The demo's stages each swap in whole: the space runs out while learning (after the
    # demonstrations), and the task's folder holds the finished demonstrate stage alone.
    argv = ["demo", "--out", "runs", "--tasks", "cotter_pin", "--no-replay", "--no-placements",
            *SMALL]  # fmt: skip
    disk.root.mkdir()
    disk.spare.mkdir()
    reference = run(["demonstrate", "cotter_pin", "--out", "probe", "--no-replay", *SMALL],
                    cwd=disk.root)  # fmt: skip
    assert reference.returncode == 0
    used = sum(-(-p.stat().st_size // PAGE) for p in (disk.root / "probe").iterdir())
    shutil.rmtree(disk.root / "probe")
    disk.leave(pages=used + 1)
    done = run(argv, cwd=disk.root, check=False)
    line = fails_in_one_line(done, "demo")
    assert NO_SPACE in line and "/runs/cotter_pin/" in line, line
    run_dir = disk.root / "runs" / "cotter_pin"
    assert not leftovers(run_dir) and not list(disk.root.rglob(".*hemg-drake-*"))
    import json

    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert sorted(manifest) == ["demonstrate"]
    disk.release()
    run(argv, cwd=disk.root)
    assert (disk.root / "runs" / "metrics.json").is_file()


@pytest.mark.slow
@pytest.mark.deep
@pytest.mark.parametrize("name", ["learn", "teleop"])
def test_an_io_error_at_each_moment_before_the_swap_names_the_file(base, tmp_path_factory, name):
    # An OSError naming no file (errno 5), raised at each fault point from the start to the
    # swap: the new version's folder, its links, each write and rename, the manifest.
    the_case = case(name, base, tmp_path_factory)
    last = next(i for i, p in enumerate(the_case.points, 1) if p.endswith("before the swap"))
    for point in range(1, last + 1):
        root = the_case.fresh(f"io-error-{point}")
        before = everything(root)
        env = {"HEMG_DRAKE_FAULT_AT": str(point), "HEMG_DRAKE_FAULT_ERRNO": "5"}
        line = fails_in_one_line(run(the_case.argv, cwd=root, check=False, env=env), name)
        target = os.path.realpath(root / the_case.folder)
        assert line.startswith(target), (the_case.points[point - 1], line)
        assert line.endswith(f": Input/output error; nothing in {target}/ was changed"), line
        assert everything(root) == before and not leftovers(root / the_case.folder)
        shutil.rmtree(root)


def test_an_error_in_the_new_version_names_the_file_where_it_will_be(tmp_path):
    from errno import EIO, ENOSPC

    from hemg_drake.fileio import named_as_moved

    built, final = tmp_path / ".run.hemg-drake-new-7", tmp_path / "run"
    said = "; nothing in " + str(final) + "/ was changed"
    error = named_as_moved(OSError(ENOSPC, NO_SPACE, str(built / "replay_1.html")), built, final)
    assert (error.errno, error.filename, error.strerror) == (ENOSPC, str(final / "replay_1.html"),
                                                             NO_SPACE + said)  # fmt: skip
    # shutil.copy2 (a link refused) names the source first and the copy second.
    copy = OSError(ENOSPC, NO_SPACE, str(final / "a.npz"), None, str(built / "a.npz"))
    copied = named_as_moved(copy, built, final)
    assert (copied.filename, copied.strerror) == (str(final / "a.npz"), NO_SPACE + said)
    assert named_as_moved(OSError(ENOSPC, NO_SPACE, str(built)), built, final).filename == str(final)
    assert named_as_moved(OSError(EIO, "Input/output error"), built, final).filename == str(final)
    elsewhere = OSError(EIO, "Input/output error", str(tmp_path / "model.npz"))
    assert named_as_moved(elsewhere, built, final) is elsewhere
    message = FileNotFoundError("run folder not found: x")  # no errno: a message of its own
    assert named_as_moved(message, built, final) is message
