"""kill -9 of ``aeroweaver sim --processes`` mid-run: how long its daemons outlive it and
how long its run directory stays behind.

``python -m aeroweaver_lab.bench.orphans --kills 5`` starts the CLI (scripted selector, one
process per daemon, its own TMPDIR), waits for a round to be flown, SIGKILLs the CLI, then
polls the process table and the filesystem (bounded by ``--bound``) until every daemon is
gone and the run's directory removed. The bench makes itself the child subreaper, so the
orphaned daemons become its children and their exit statuses are counted (a clean stop on
the parent-death SIGTERM exits 0). Prints one JSON line; exit status 1 if a daemon or the
directory outlived the bound (an orphan). Linux (reads /proc).
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from aeroweaver_edge.orchestration.swarm import percentiles


def running(pid: int) -> bool:
    """Whether ``pid`` is a live process (a zombie is not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


def children(pid: int) -> list[int]:
    """Live processes whose parent is ``pid``."""
    out = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        if ppid == pid and running(int(entry.name)):
            out.append(int(entry.name))
    return out


PR_SET_CHILD_SUBREAPER = 36  # <linux/prctl.h>


def _become_subreaper() -> bool:
    libc = ctypes.CDLL(None, use_errno=True)
    return bool(libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0)


def _reap(pid: int, exits: dict[int, str]) -> None:
    """Collect ``pid``'s exit status if it is our (adopted) child and has ended."""
    if pid in exits:
        return
    try:
        done, status = os.waitpid(pid, os.WNOHANG)
    except ChildProcessError:
        return  # not ours (no subreaper): /proc tells whether it runs
    if done == pid:
        if os.WIFSIGNALED(status):
            exits[pid] = signal.Signals(os.WTERMSIG(status)).name
        else:
            exits[pid] = f"exit {os.WEXITSTATUS(status)}"


def one_kill(bound_s: float) -> dict[str, Any]:
    """One run killed after its first round; seconds until its daemons and dir are gone
    (None: still there at the bound)."""
    tmp = Path(tempfile.mkdtemp(prefix="aw-orphans-"))
    proc = subprocess.Popen(
        [sys.executable, "-m", "aeroweaver_edge", "sim", "coverage", "--selector",
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
        daemons = children(proc.pid)
        [run_dir] = [p for p in tmp.iterdir() if p.name.startswith("aeroweaver-")]
        killed = time.monotonic()
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        gone: float | None = None
        removed: float | None = None
        exits: dict[int, str] = {}
        while time.monotonic() - killed < bound_s and (gone is None or removed is None):
            now = time.monotonic() - killed
            for pid in daemons:
                _reap(pid, exits)
            if gone is None and not any(running(p) for p in daemons):
                gone = now
            if removed is None and not run_dir.exists():
                removed = now
            time.sleep(0.01)
        left: dict[str, Any] | None = None
        if removed is None and run_dir.exists():
            left = {"files": sorted(os.listdir(run_dir))}
            for log in sorted(run_dir.glob("*.log")):  # how each daemon ended
                left[log.name] = log.read_text(errors="replace").splitlines()[-3:]
        settle = time.monotonic() + 5.0  # the last ones may still be on their way out
        while len(exits) < len(daemons) and time.monotonic() < settle:
            for pid in daemons:
                _reap(pid, exits)
            time.sleep(0.01)
        return {
            "exits": list(exits.values()),
            "daemons": len(daemons),
            "daemons_gone_s": gone,
            "dir_removed_s": removed,
            "left": left,  # what a directory left behind still held (to tell why)
        }
    finally:
        for pid in [proc.pid, *daemons]:
            if running(pid):
                os.kill(pid, signal.SIGKILL)
        proc.wait()
        shutil.rmtree(tmp, ignore_errors=True)


def run(kills: int, bound_s: float = 30.0) -> dict[str, Any]:
    subreaper = _become_subreaper()
    lives = [one_kill(bound_s) for _ in range(kills)]
    exits = Counter(e for x in lives for e in x["exits"])
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
        "daemon_exits": dict(exits) if subreaper else "unknown (no child subreaper)",
        "left_behind": [x["left"] for x in lives if x["left"] is not None],
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m aeroweaver_lab.bench.orphans", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--kills", type=int, default=5)
    parser.add_argument("--bound", type=float, default=30.0, help="seconds an orphan may live")
    args = parser.parse_args(argv)
    out = run(args.kills, args.bound)
    print(json.dumps(out))
    return 1 if out["orphaned_daemons"] or out["dirs_left"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
