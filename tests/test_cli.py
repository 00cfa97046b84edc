"""The `hemg-drake demo` command line."""

import subprocess
import sys

from hemg_drake.cli import main


def test_demo_unknown_task_is_one_line_error(tmp_path, capsys):
    # The full demo itself is tested at small scale in tests/test_pipeline.py.
    assert main(["demo", "--out", str(tmp_path), "--tasks", "juggling"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("hemg-drake demo: error:") and "juggling" in err
    assert len(err.splitlines()) == 1
    assert not any(tmp_path.iterdir())


def test_console_entry_point_help():
    result = subprocess.run(
        [sys.executable, "-m", "hemg_drake.cli", "demo", "--help"], capture_output=True, text=True
    )
    assert result.returncode == 0 and "--tasks" in result.stdout
