"""The earlier runs every fault test starts from: built once per pytest run, shared by its
xdist workers (the tests only copy it)."""

import fcntl
import shutil

import pytest

from tooling.faults import make_base


@pytest.fixture(scope="session")
def base(tmp_path_factory, worker_id):
    if worker_id == "master":  # not under xdist
        return make_base(tmp_path_factory.mktemp("base"))
    # The workers' temporary folders share a parent: the first worker to take the lock builds
    # the runs there (half a minute of six commands), the others wait and reuse them.
    shared = tmp_path_factory.getbasetemp().parent
    with open(shared / "faults_base.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        root, built = shared / "faults_base", shared / "faults_base.built"
        if not built.exists():  # (a worker that failed midway left a partial one)
            shutil.rmtree(root, ignore_errors=True)
            make_base(root)
            built.touch()
    return root
