"""The Ray backend for real: the same tiny sweep as the local backend gives the same table.

Ray binds the host's own address unless told otherwise and probes outside addresses, so
these tests run only inside a network namespace whose only device is the loopback
(``.ci/run``: ``unshare -n``, ``ip link set lo up``, then this file with
``HEMG_DRAKE_RAY_TESTS=1``); they skip anywhere else.
"""

import csv
import os
from pathlib import Path

import pytest

from hemg_drake.sweep import only_loopback as _only_loopback
from hemg_drake.sweep import run_sweep


pytestmark = [
    pytest.mark.skipif(
        os.environ.get("HEMG_DRAKE_RAY_TESTS") != "1" or not _only_loopback(),
        reason="Ray tests run only in a loopback-only network namespace (.ci/run) with "
        "HEMG_DRAKE_RAY_TESTS=1",
    ),
]

SWEEP = """\
scenario: cotter_pin
set: [num_demonstrations=2, duration=1.0, learning.n_iter=3, learning.num_states=2,
      reproduction.settle_time=0.2]
axes:
  - {name: emg.window, values: [10, 30]}
  - {name: learning.num_states, values: [2, 90]}   # 90: too many for the data, fails at learn
seeds: [3]
metrics: [demonstration.tracking_error_m, reproduction.position_rmse_m]
"""


def _table(path):
    with open(path, newline="") as f:
        return [{k: v for k, v in row.items() if k != "elapsed_s"} for row in csv.DictReader(f)]


def test_ray_gives_the_same_table_as_the_local_backend(tmp_path):
    pytest.importorskip("ray")
    path = tmp_path / "tiny.yaml"
    path.write_text(SWEEP)
    local = run_sweep(path, tmp_path / "local", workers=2)
    remote = run_sweep(path, tmp_path / "ray", backend="ray", workers=2)
    assert [r["status"] for r in remote] == ["done", "failed", "done", "failed"]
    assert [r["id"] for r in local] == [r["id"] for r in remote]
    assert _table(tmp_path / "local" / "results.csv") == _table(tmp_path / "ray" / "results.csv")
    for record in remote:
        assert (Path(tmp_path / "ray" / "trials" / record["id"]) / "trial.json").is_file()
