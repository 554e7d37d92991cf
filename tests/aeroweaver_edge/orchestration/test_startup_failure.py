"""A daemon that fails at start-up is reported within seconds, in one line of its own.

Before: ``aeroweaver sim --processes`` waited out the whole start-up wait (20 s + 3 s per
UAV) for the liveliness token of a daemon that had exited 2 at once, then another 15 s for
the healthy daemons to stop by themselves, and printed a dict with the child's log tail:
43 s for 2 UAVs on a loaded 2-core box. The real CLI, real daemon processes."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aeroweaver_edge.agent.memory.tools import check_file

pytestmark = pytest.mark.slow

UAVS = 3
OLD_WAIT_S = 20.0 + 3.0 * UAVS  # what the run used to wait before saying anything


def test_a_daemon_exiting_at_start_up_fails_the_run_at_once(tmp_path: Path) -> None:
    memory = tmp_path / "memory"
    (memory / "uav1.sqlite3").mkdir(parents=True)  # uav1's memory file is a directory
    run_tmp = tmp_path / "tmp"
    run_tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(run_tmp), "PYTHONUNBUFFERED": "1"}
    started = time.monotonic()
    args = [
        sys.executable, "-m", "aeroweaver_edge", "sim", "--processes",
        "--uavs", str(UAVS), "--rounds", "3", "--selector", "scripted",
        "--memory-dir", str(memory), "--quiet",
    ]  # fmt: skip
    proc = subprocess.run(
        args,
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=False,
    )
    took = time.monotonic() - started
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 1, proc.stderr
    assert len(lines) == 1, proc.stderr  # no "left the swarm" warnings, no traceback
    assert lines[0].startswith("aeroweaver: run failed: daemon failed at start-up: uav1 (exit 2)")
    assert "uav1.sqlite3 is a directory" in lines[0]  # the child's own line
    assert took < OLD_WAIT_S - 6.0, f"reported after {took:.1f} s"
    # the healthy daemons were stopped with the run, and nothing of the run is left
    assert sorted(p.name for p in run_tmp.iterdir()) == []
    # A healthy daemon stopped before it opened its memory has no file (the run fails at
    # once, so that is a race); whatever was opened was closed whole.
    files = {p.name for p in memory.iterdir()} - {"uav1.sqlite3"}
    assert files <= {"uav0.sqlite3", "uav2.sqlite3"}, files  # no -wal / -shm left open
    assert all(check_file(memory / name) == [] for name in files)
