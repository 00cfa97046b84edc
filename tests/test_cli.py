"""The `hemg-drake demo` command line."""

import subprocess
import sys

from hemg_drake.cli import main


def test_demo_writes_replay_and_says_where(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--duration", "0.3"]) == 0
    replay = out / "replay.html"
    assert replay.is_file() and replay.stat().st_size > 100_000
    assert f"wrote {replay}" in capsys.readouterr().out


def test_demo_bad_duration_is_one_line_error(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--duration", "-1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("hemg-drake demo: error:") and "duration" in err
    assert len(err.splitlines()) == 1
    assert not (tmp_path / "replay.html").exists()


def test_console_entry_point_help():
    result = subprocess.run(
        [sys.executable, "-m", "hemg_drake.cli", "demo", "--help"], capture_output=True, text=True
    )
    assert result.returncode == 0 and "--duration" in result.stdout
