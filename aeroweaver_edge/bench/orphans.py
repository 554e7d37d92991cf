"""kill -9 of ``aeroweaver sim --processes`` mid-run: how long its daemons outlive it and
how long its run directory stays behind.

``python -m aeroweaver_edge.bench.orphans --kills 5`` starts the CLI (scripted selector, one
process per daemon, its own TMPDIR), waits for a round to be flown, SIGKILLs the CLI, then
polls the process table and the filesystem (bounded by ``--bound``) until every daemon is
gone and the run's directory removed. Prints one JSON line; exit status 1 if a daemon or
the directory outlived the bound (an orphan). Linux (reads /proc).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from aeroweaver_edge.orchestration.swarm import percentiles


def _running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


def _children(pid: int) -> list[int]:
    out = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        if ppid == pid and _running(int(entry.name)):
            out.append(int(entry.name))
    return out


def one_kill(bound_s: float) -> dict[str, Any]:
    """One run killed after its first round; seconds until its daemons and dir are gone
    (None: still there at the bound)."""
    tmp = Path(tempfile.mkdtemp(prefix="aw-orphans-"))
    proc = subprocess.Popen(
        [sys.executable, "-m", "aeroweaver_edge.cli", "sim", "coverage", "--selector",
         "scripted", "--processes", "--episodes", "500"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
        env={**os.environ, "TMPDIR": str(tmp), "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    daemons: list[int] = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.startswith("ep ") and " round " in line:
                break
        else:
            raise RuntimeError(f"the run ended before its first round (exit {proc.wait()})")
        daemons = _children(proc.pid)
        [run_dir] = [p for p in tmp.iterdir() if p.name.startswith("aeroweaver-")]
        killed = time.monotonic()
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        gone: float | None = None
        removed: float | None = None
        while time.monotonic() - killed < bound_s and (gone is None or removed is None):
            now = time.monotonic() - killed
            if gone is None and not any(_running(p) for p in daemons):
                gone = now
            if removed is None and not run_dir.exists():
                removed = now
            time.sleep(0.01)
        left = sorted(os.listdir(run_dir)) if removed is None and run_dir.exists() else None
        return {
            "daemons": len(daemons),
            "daemons_gone_s": gone,
            "dir_removed_s": removed,
            "left": left,  # what a directory left behind still held (to tell why)
        }
    finally:
        for pid in [proc.pid, *daemons]:
            if _running(pid):
                os.kill(pid, signal.SIGKILL)
        proc.wait()
        shutil.rmtree(tmp, ignore_errors=True)


def run(kills: int, bound_s: float = 30.0) -> dict[str, Any]:
    lives = [one_kill(bound_s) for _ in range(kills)]
    gone = [x["daemons_gone_s"] for x in lives if x["daemons_gone_s"] is not None]
    removed = [x["dir_removed_s"] for x in lives if x["dir_removed_s"] is not None]
    return {
        "kills": kills,
        "daemons_killed_with_it": sum(x["daemons"] for x in lives),
        "orphaned_daemons": sum(x["daemons"] for x in lives if x["daemons_gone_s"] is None),
        "dirs_left": kills - len(removed),
        "bound_s": bound_s,
        "daemons_gone_s": percentiles(gone),
        "dir_removed_s": percentiles(removed),
        "left_behind": [x["left"] for x in lives if x["left"] is not None],
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m aeroweaver_edge.bench.orphans", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--kills", type=int, default=5)
    parser.add_argument("--bound", type=float, default=30.0, help="seconds an orphan may live")
    args = parser.parse_args(argv)
    out = run(args.kills, args.bound)
    print(json.dumps(out))
    return 1 if out["orphaned_daemons"] or out["dirs_left"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
