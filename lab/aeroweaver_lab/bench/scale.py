"""Scale benchmark: one simulated episode per swarm size, one JSON line per size.

``aeroweaver bench scale`` (or ``python -m aeroweaver_lab.bench.scale``) flies the task
(coverage by default: N UAVs, N landmarks) with the scripted reference selector, one OS
process per daemon unless ``--in-process``, and prints for each size:

* ``round_wall_s``: the world's wall time per round (perceptions out to rewards out), p50/p95;
* ``decision_s``: each daemon's wall time per decision (observe to act), p50/p95, and
  ``decision_cpu_s``: the daemon thread's CPU time per decision (meaningful with one
  process per daemon: in-process it includes the other daemons' work);
* ``messages_per_round``: (message, recipient) pairs delivered per round, and
  ``broadcasts_per_round``: messages sent per round;
* ``peak_rss_mb``: peak resident memory (``VmHWM``) per daemon process, max and mean;
* ``deadline_misses``, rounds, the episode's end and its wall time.

Figures depend on the machine and its load: re-run on an idle machine before quoting them.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sys
from typing import Any

from aeroweaver_edge.contracts.defaults import DEADLINE_S, MAX_ROUNDS
from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm


async def measure(task: str, n: int, *, processes: bool, rounds: int, seed: int) -> dict[str, Any]:
    opts = SwarmOptions(
        task=task,
        uavs=n,
        seed=seed,
        max_rounds=rounds,
        processes=processes,
        selector="scripted",
        measure_rss=processes,
        deadline_s=DEADLINE_S,
    )
    s = (await run_swarm(opts)).as_dict()
    played = max(1, s["rounds"])
    rss = [kb / 1024 for kb in s["peak_rss_kb"].values()]
    return {
        "task": task,
        "uavs": n,
        "mode": s["mode"],
        "rounds": s["rounds"],
        "end": s["episodes"][0]["reason"],
        "round_wall_s": {k: v for k, v in s["round_wall_s"].items() if k in ("p50", "p95")},
        "decision_s": {k: v for k, v in s["decision_latency_s"].items() if k in ("p50", "p95")},
        "decision_cpu_s": {k: v for k, v in s["decision_cpu_s"].items() if k in ("p50", "p95")},
        "messages_per_round": round(s["deliveries"] / played, 1),
        "broadcasts_per_round": round(s["messages_sent"] / played, 1),
        "peak_rss_mb": (
            {"max": round(max(rss), 1), "mean": round(math.fsum(rss) / len(rss), 1)}
            if rss
            else None
        ),
        "deadline_misses": s["deadline_misses"],
        "team_return": round(s["team_return"], 3),
        "wall_s": s["wall_s"],
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="aeroweaver bench scale", description=__doc__)
    p.add_argument("--sizes", type=int, nargs="+", default=[3, 10, 25, 50])
    p.add_argument("--task", default="coverage")
    p.add_argument("--rounds", type=int, default=MAX_ROUNDS)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--in-process", action="store_true")
    args = p.parse_args(argv)
    for n in args.sizes:
        row = asyncio.run(
            measure(args.task, n, processes=not args.in_process, rounds=args.rounds, seed=args.seed)
        )
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
