"""kill -9 and restart of daemons inside running simulated swarms: they rejoin, nothing lost.

``python -m aeroweaver_lab.bench.kill_restart --cycles 200`` (or ``aeroweaver bench
kill-restart --kills 200``) runs simulated swarms with one OS process per daemon
(``sim --processes``, scripted selector, every run on one memory directory) and, between
rounds, SIGKILLs a random daemon that is up and starts it again at once from its config, as
systemd's ``Restart=`` would. Runs follow one another until ``--cycles`` kill/restart
cycles have happened. For every cycle it measures restart-to-rejoin (the new process
caught up its assignment: its "ready" report for the running mission) and
restart-to-first-round (it decided a round again). Over a run's last episode no daemon is
killed, and the world waits (bounded) for every restarted daemon to be back.

After every run: the run completed (every episode, no daemon failed), and each daemon's
memory file passes ``aeroweaver memory check`` (integrity, every reward on its own
decision, every return recomputable). Records lost: a daemon reports a round before it
stores it, so of each daemon life every reported decision but the last is acknowledged
(the next round starts only after the store) -- each must be in that daemon's memory; the
last reported round of a killed life was in flight and is not counted. A life that was not
killed must have stored every reported decision. Prints one JSON line of figures; exit
status 1 if a record was lost, a check failed or a run did not complete.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import random
import sqlite3
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aeroweaver_edge.agent.memory.tools import check, memory_files
from aeroweaver_edge.contracts.errors import RunFailed
from aeroweaver_edge.contracts.wire import ProgressReport
from aeroweaver_edge.orchestration.daemons import DaemonSet
from aeroweaver_edge.orchestration.swarm import SwarmOptions, percentiles, run_swarm
from aeroweaver_edge.sim.runner import RoundLog
from commander.commander import Commander

log = logging.getLogger(__name__)

REJOIN_WAIT_S = 90.0  # the last episode waits this long for every restarted daemon


@dataclass
class Life:
    """One process of one daemon, known by the boot epoch its reports carry."""

    uav: str
    epoch: int
    rounds: list[tuple[int, int]] = field(default_factory=list)  # reported decisions
    killed: bool = False


@dataclass
class RunTally:
    """What one run saw: lives, restarts waiting to rejoin, rejoin times."""

    lives: dict[tuple[str, int], Life] = field(default_factory=dict)
    current: dict[str, int] = field(default_factory=dict)  # uav -> epoch of its live process
    restarted_at: dict[str, float] = field(default_factory=dict)  # uav -> restart, not back yet
    ready_at: dict[str, float] = field(default_factory=dict)  # uav -> restart, ready, no round yet
    rejoin_s: list[float] = field(default_factory=list)  # restart -> assignment caught up
    flying_s: list[float] = field(default_factory=list)  # restart -> first round decided
    kills: int = 0
    changed: asyncio.Event = field(default_factory=asyncio.Event)

    def on_report(self, rep: ProgressReport) -> None:
        if rep.phase not in ("ready", "round"):
            return
        self.changed.set()
        key = (rep.uav, rep.h.epoch)
        life = self.lives.get(key)
        if life is None:
            if rep.h.epoch < self.current.get(rep.uav, 0):
                return  # a late report of a killed life: nothing to learn
            life = self.lives[key] = Life(rep.uav, rep.h.epoch)
            self.current[rep.uav] = rep.h.epoch
        restarted = self.restarted_at.get(rep.uav)
        if restarted is not None and rep.phase == "ready":
            self.rejoin_s.append(time.monotonic() - restarted)  # caught up its assignment
            self.ready_at[rep.uav] = restarted
            del self.restarted_at[rep.uav]
        if rep.phase != "round":
            return
        restarted = self.ready_at.pop(rep.uav, None)
        if restarted is not None:
            self.flying_s.append(time.monotonic() - restarted)  # decided again
        if rep.label is not None:  # the agent chose: the daemon stores it next
            life.rounds.append((rep.episode, rep.round))

    def up(self) -> list[str]:
        """Daemons whose current process has rejoined and decided a round since."""
        return [u for u in self.current if u not in self.restarted_at and u not in self.ready_at]


async def _one_run(
    opts: SwarmOptions, rng: random.Random, cycles_left: int, kill_p: float, tally: RunTally
) -> dict[str, Any]:
    last_episode = opts.episodes - 1

    async def fault(log_: RoundLog, daemons: DaemonSet) -> None:
        if log_.episode >= last_episode:
            # The last episode: every restarted daemon must have caught up before the run
            # ends, or it could miss the world's shutdown (bounded; the world waits with us).
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(REJOIN_WAIT_S):
                    while tally.restarted_at:
                        tally.changed.clear()
                        await tally.changed.wait()
            return
        up = tally.up()
        if tally.kills >= cycles_left or len(up) <= len(tally.current) // 2:
            return  # keep at least half of the swarm up
        for uav in sorted(up):
            if rng.random() < kill_p and tally.kills < cycles_left:
                life = tally.lives.get((uav, tally.current[uav]))
                if life is not None:
                    life.killed = True
                await daemons.kill(uav)
                tally.restarted_at[uav] = time.monotonic()
                tally.kills += 1
                await daemons.restart(uav)
                break  # one kill per round

    def attach(commander: Commander) -> None:
        commander.report_listeners.append(tally.on_report)

    summary = await run_swarm(opts, fault=fault, on_commander=attach)
    return summary.as_dict()


def _lost(memory_dir: Path, run_id: str, tally: RunTally) -> list[str]:
    """Acknowledged decisions missing from their daemon's memory."""
    lost: list[str] = []
    for life in tally.lives.values():
        want = life.rounds[:-1] if life.killed else life.rounds
        path = memory_dir / f"{life.uav}.sqlite3"
        with sqlite3.connect(f"file:{path}?mode=ro", uri=True) as conn:
            have = set(
                conn.execute(
                    "SELECT episode, round FROM records WHERE run = ? AND uav = ? AND origin = ''",
                    (run_id, life.uav),
                ).fetchall()
            )
        lost += [f"{life.uav}/{e}/{r}" for e, r in want if (e, r) not in have]
    return lost


def run(
    cycles: int,
    *,
    uavs: int = 6,
    episodes: int = 8,
    task: str = "coverage",
    kill_p: float = 0.3,
    seed: int = 0,
    max_runs: int = 200,
    memory_dir: Path | None = None,
) -> dict[str, Any]:
    """Runs until ``cycles`` kill/restart cycles happened; returns the figures."""
    rng = random.Random(seed)
    started = time.monotonic()
    out: dict[str, Any] = {
        "cycles": 0, "runs": 0, "completed_runs": 0, "failed_runs": [], "records_checked": 0,
        "records_lost": 0, "lost": [], "check_problems": 0, "world_rejoins": 0,
        "barrier_timeouts": 0, "rounds": 0, "deadline_misses": 0,
    }  # fmt: skip
    rejoin: list[float] = []
    flying: list[float] = []
    with tempfile.TemporaryDirectory(prefix="aw-kill-restart-") as tmp:
        mem = memory_dir or Path(tmp)
        while out["cycles"] < cycles and out["runs"] < max_runs:
            tally = RunTally()
            opts = SwarmOptions(
                task=task, uavs=uavs, seed=seed + out["runs"], episodes=episodes,
                processes=True, selector="scripted", memory_dir=mem, deadline_s=5.0,
            )  # fmt: skip
            out["runs"] += 1
            try:
                data = asyncio.run(_one_run(opts, rng, cycles - out["cycles"], kill_p, tally))
            except RunFailed as exc:
                out["failed_runs"].append(str(exc)[:300])
                out["cycles"] += tally.kills
                continue
            out["cycles"] += tally.kills
            out["completed_runs"] += len(data["episodes"]) == episodes
            out["rounds"] += data["rounds"]
            out["deadline_misses"] += data["deadline_misses"]
            out["world_rejoins"] += sum(data["rejoined_uavs"].values())
            out["barrier_timeouts"] += data["experience_barrier"].get("timeouts", 0)
            rejoin += tally.rejoin_s
            flying += tally.flying_s
            lost = _lost(mem, data["run_id"], tally)
            out["records_checked"] += sum(
                len(life.rounds) - life.killed for life in tally.lives.values()
            )
            out["records_lost"] += len(lost)
            out["lost"] += lost[:10]
            problems = check(memory_files(mem))
            out["check_problems"] += sum(len(p) for p in problems.values())
        out["restart_to_rejoin_s"] = percentiles(rejoin)
        out["restart_to_first_round_s"] = percentiles(flying)
        out["rejoins_measured"] = len(rejoin)
        out["wall_s"] = round(time.monotonic() - started, 1)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m aeroweaver_lab.bench.kill_restart", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--cycles", type=int, default=200, help="kill/restart cycles in total")
    parser.add_argument("--uavs", type=int, default=6)
    parser.add_argument("--episodes", type=int, default=8, help="episodes per run")
    parser.add_argument("--task", default="coverage")
    parser.add_argument("--kill-p", type=float, default=0.3, help="per-round kill chance")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    result = run(
        args.cycles, uavs=args.uavs, episodes=args.episodes, task=args.task,
        kill_p=args.kill_p, seed=args.seed,
    )  # fmt: skip
    print(json.dumps(result))
    bad = (
        result["records_lost"]
        or result["check_problems"]
        or result["failed_runs"]
        or result["completed_runs"] != result["runs"]
    )
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
