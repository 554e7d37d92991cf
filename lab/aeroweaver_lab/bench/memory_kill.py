"""kill -9 benchmark for the experience memory: nothing acknowledged is ever lost.

``python -m aeroweaver_lab.bench.memory_kill --kills 200`` runs ``--kills`` lives. In each
life ``--writers`` processes (default 2: two runs sharing one file, as two simulated runs
on one ``--memory-dir`` do) write one SQLite file through the daemon's own write path
(``AsyncExperienceMemory``: a decision per round, the previous round's reward, finalise
at episode end) and print one acknowledgement line *after* each commit. Each writer gets
SIGKILL at a random moment (uniform in ``[0, --max-life-s]`` after it is ready), in the
middle of its stream of writes. After every life the file is checked read-only:
``PRAGMA integrity_check``, every acknowledged decision present with its skill, every
acknowledged reward stored and attached to its own decision, every acknowledged
finalisation applied, and the full consistency check of ``aeroweaver memory check``.
The next life's writers reopen the file as restarted daemons do (new run identities).

Prints one JSON line of figures: kills, integrity failures, acknowledged writes, records
lost (must be 0), consistency problems, quarantines. Exit status 1 if anything was lost.
SIGKILL proves crash consistency of the process, not durability on power loss.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

TASK, ROLE = "coverage", "searcher"
ROUNDS = 24
SKILLS = ("cover_landmark", "explore_local", "hold_position", "send_status")


# --------------------------------------------------------------------------- the writer


async def _write_forever(path: Path, run: str, uavs: Sequence[str], seed: int) -> None:
    from aeroweaver_edge.agent.memory.async_memory import AsyncExperienceMemory

    rng = random.Random(seed)
    mem = await AsyncExperienceMemory.open(path, run=run, required=True)
    out = sys.stdout
    out.write(f"READY {run}\n")
    out.flush()
    episode = 0
    while True:
        for rnd in range(ROUNDS + 1):
            for uav in uavs:
                if rnd > 0:  # the world's reward for the previous round arrives first
                    reward = round(rng.uniform(-2.0, 1.0), 6)
                    if await mem.add_reward(uav, episode, rnd - 1, reward, "bench"):
                        out.write(f"R {uav} {episode} {rnd - 1} {reward!r}\n")
                        out.flush()
                if rnd < ROUNDS:
                    skill = rng.choice(SKILLS)
                    state = f"task {TASK} role {ROLE} self {uav} round {rnd} x {rng.randint(0, 9)}"
                    stored = await mem.append(
                        task=TASK,
                        role=ROLE,
                        uav=uav,
                        episode=episode,
                        round=rnd,
                        state_text=state,
                        skill=skill,
                        invocation=f"{skill}()",
                    )
                    if stored:
                        out.write(f"A {uav} {episode} {rnd} {skill}\n")
                        out.flush()
        for uav in uavs:
            n = await mem.finalise(uav, episode)
            out.write(f"F {uav} {episode} {n}\n")
            out.flush()
        episode += 1


def _writer_main(args: argparse.Namespace) -> int:
    asyncio.run(_write_forever(Path(args.writer), args.run, args.uavs.split(","), args.seed))
    return 0  # pragma: no cover - the parent always kills the writer


# --------------------------------------------------------------------------- the checker


@dataclass
class Acks:
    """What one writer acknowledged before it died."""

    run: str
    appends: dict[tuple[str, int, int], str] = field(default_factory=dict)
    rewards: dict[tuple[str, int, int], float] = field(default_factory=dict)
    finals: set[tuple[str, int]] = field(default_factory=set)

    def parse(self, line: str) -> None:
        parts = line.split()
        if not parts:
            return
        if parts[0] == "A":
            self.appends[(parts[1], int(parts[2]), int(parts[3]))] = parts[4]
        elif parts[0] == "R":
            self.rewards[(parts[1], int(parts[2]), int(parts[3]))] = float(parts[4])
        elif parts[0] == "F":
            self.finals.add((parts[1], int(parts[2])))

    @property
    def count(self) -> int:
        return len(self.appends) + len(self.rewards) + len(self.finals)


def lost_records(path: Path, acks: list[Acks]) -> list[str]:
    """Every acknowledged write missing from (or different in) the file."""
    conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=10.0)
    try:
        records = {
            (run, uav, ep, rnd): (skill, reward, final)
            for run, uav, ep, rnd, skill, reward, final in conn.execute(
                "SELECT run, uav, episode, round, skill, reward, final FROM records"
            )
        }
        rewards = {
            (run, uav, ep, rnd): reward
            for run, uav, ep, rnd, reward in conn.execute(
                "SELECT run, uav, episode, round, reward FROM rewards"
            )
        }
    finally:
        conn.close()
    lost: list[str] = []
    for a in acks:
        for (uav, ep, rnd), skill in a.appends.items():
            got = records.get((a.run, uav, ep, rnd))
            if got is None or got[0] != skill:
                lost.append(f"decision {a.run}/{uav}/{ep}/{rnd}: {got}")
        for (uav, ep, rnd), reward in a.rewards.items():
            if rewards.get((a.run, uav, ep, rnd)) != reward:
                lost.append(f"reward {a.run}/{uav}/{ep}/{rnd}")
            rec = records.get((a.run, uav, ep, rnd))
            if (uav, ep, rnd) in a.appends and (rec is None or rec[1] != reward):
                lost.append(f"reward not on its decision {a.run}/{uav}/{ep}/{rnd}")
        for uav, ep in a.finals:
            for u, e, rnd in a.appends:
                rec = records.get((a.run, u, e, rnd))
                if (u, e) == (uav, ep) and (rec is None or not rec[2]):
                    lost.append(f"finalisation {a.run}/{uav}/{ep}/{rnd}")
    return lost


def _integrity(path: Path) -> bool:
    conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=10.0)
    try:
        return bool(conn.execute("PRAGMA integrity_check").fetchall() == [("ok",)])
    finally:
        conn.close()


# --------------------------------------------------------------------------- the harness


def _spawn(path: Path, run: str, uavs: str, seed: int) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "aeroweaver_lab.bench.memory_kill", "--writer", str(path),
         "--run", run, "--uavs", uavs, "--seed", str(seed)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )  # fmt: skip


def _wait_ready(proc: subprocess.Popen[str]) -> None:
    assert proc.stdout is not None
    line = proc.stdout.readline()  # bounded: the writer prints READY or dies (EOF)
    if not line.startswith("READY"):
        err = proc.stderr.read() if proc.stderr is not None else ""
        raise RuntimeError(f"writer did not start: {line!r} {err[-2000:]}")


def run(
    kills: int,
    *,
    writers: int = 2,
    max_life_s: float = 0.4,
    seed: int = 0,
    directory: Path | None = None,
) -> dict[str, Any]:
    """Run the kill loop on a memory file in ``directory`` (default: a temporary one)."""
    if kills < 1 or writers < 1:
        raise ValueError("kills and writers must be at least 1")
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory(prefix="aw-kill-") as tmp:
        path = (directory or Path(tmp)) / "uav0.sqlite3"
        all_acks: list[Acks] = []
        integrity_failures = 0
        killed_mid_write = 0
        started = time.monotonic()
        life = 0
        while life * writers < kills:
            procs = []
            for w in range(writers):
                acks = Acks(run=f"life{life:04d}-w{w}")
                all_acks.append(acks)
                procs.append((_spawn(path, acks.run, "uav0,uav1", seed + life * writers + w), acks))
            for proc, _ in procs:
                _wait_ready(proc)
            for proc, _acks in sorted(procs, key=lambda _: rng.random()):
                time.sleep(rng.uniform(0.0, max_life_s / writers))
                os.kill(proc.pid, signal.SIGKILL)
            for proc, acks in procs:
                assert proc.stdout is not None
                assert proc.stderr is not None
                # Read through the same buffered file as READY was read (communicate()
                # would skip what readline() had already buffered), up to EOF: the writer
                # is dead, so everything it acknowledged is in the pipe.
                out = proc.stdout.read()
                proc.stderr.read()
                proc.wait()
                proc.stdout.close()
                proc.stderr.close()
                for line in out.splitlines():
                    acks.parse(line)
                killed_mid_write += proc.returncode == -signal.SIGKILL
            if not _integrity(path):
                integrity_failures += 1
            life += 1
        from aeroweaver_edge.agent.memory.tools import check_file

        lost = lost_records(path, all_acks)
        problems = check_file(path)
        quarantined = sorted(p.name for p in path.parent.glob("*.corrupt-*"))
        conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        stored = conn.execute("SELECT count(*) FROM records").fetchone()[0]
        conn.close()
    return {
        "kills": life * writers,
        "killed_mid_write": killed_mid_write,
        "writers_per_life": writers,
        "integrity_failures": integrity_failures,
        "acknowledged_writes": sum(a.count for a in all_acks),
        "acknowledged_decisions": sum(len(a.appends) for a in all_acks),
        "records_stored": stored,
        "records_in_flight": stored - sum(len(a.appends) for a in all_acks),
        "records_lost": len(lost),
        "lost_examples": lost[:5],
        "consistency_problems": len(problems),
        "problem_examples": problems[:5],
        "quarantined": len(quarantined),
        "wall_s": round(time.monotonic() - started, 1),
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m aeroweaver_lab.bench.memory_kill", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--kills", type=int, default=200, help="SIGKILLs in total")
    parser.add_argument("--writers", type=int, default=2, help="concurrent writers per life")
    parser.add_argument("--max-life-s", type=float, default=0.4, help="longest life after ready")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--writer", help=argparse.SUPPRESS)  # internal: be a writer
    parser.add_argument("--run", default="", help=argparse.SUPPRESS)
    parser.add_argument("--uavs", default="uav0", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.writer:
        return _writer_main(args)
    result = run(args.kills, writers=args.writers, max_life_s=args.max_life_s, seed=args.seed)
    print(json.dumps(result))
    bad = result["records_lost"] or result["integrity_failures"] or result["consistency_problems"]
    return 1 if bad or result["quarantined"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
