"""Scripted-reference returns per task: the benchmark's sanity bound, seeds x tasks.

``aeroweaver bench reference`` (or ``python -m aeroweaver_lab.bench.reference``) flies every
task (or ``--tasks``) with the task's scripted reference policy, the default team, one
episode per seed, daemons in this process (returns equal the ``--processes`` ones, which a
test checks), and prints one JSON line per run and a Markdown table of the team mean return
(mean ± sample SD over the seeds). These are a heuristic's returns: a bound to compare LLM
conditions against, never evidence about an LLM.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
from typing import Any

from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm
from aeroweaver_edge.tasks import TASK_NAMES, canonical_task


async def one(task: str, seed: int, uavs: int | None) -> dict[str, Any]:
    opts = SwarmOptions(task=task, uavs=uavs, seed=seed, selector="scripted", deadline_s=10.0)
    s = (await run_swarm(opts)).as_dict()
    ep = s["episodes"][0]
    return {
        "task": task,
        "seed": seed,
        "uavs": s["uavs"],
        "team_return": ep["team_return"],
        "rounds": ep["rounds"],
        "end": ep["reason"],
        "metrics": ep["metrics"],
    }


def table(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| task | UAVs | team return (mean ± SD) | rounds (mean) | complete |",
        "|---|---|---|---|---|",
    ]
    for task in dict.fromkeys(r["task"] for r in rows):
        mine = [r for r in rows if r["task"] == task]
        ret = [r["team_return"] for r in mine]
        sd = statistics.stdev(ret) if len(ret) > 1 else 0.0
        rounds = statistics.fmean(r["rounds"] for r in mine)
        done = sum(r["end"] == "complete" for r in mine)
        lines.append(
            f"| {task} | {mine[0]['uavs']} | {statistics.fmean(ret):.3f} ± {sd:.3f} | "
            f"{rounds:.1f} | {done}/{len(mine)} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="aeroweaver bench reference", description=__doc__)
    p.add_argument(
        "--tasks", nargs="+", type=canonical_task, choices=TASK_NAMES, default=list(TASK_NAMES)
    )
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    p.add_argument("--uavs", type=int, default=None, help="default: each task's team size")
    args = p.parse_args(argv)
    rows = []
    for task in args.tasks:
        for seed in args.seeds:
            row = asyncio.run(one(task, seed, args.uavs))
            rows.append(row)
            print(json.dumps(row), flush=True)
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
