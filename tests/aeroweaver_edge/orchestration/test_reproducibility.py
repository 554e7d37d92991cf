"""Multi-episode runs with the experience correction on (beta = 0.8) are reproducible: the
same returns in-process and with one process per daemon, because shared experience crosses
a barrier between episodes and is stored in one canonical order (before: a fixed 0.3 s
sleep, and records stored in arrival order, gave different returns run to run).

The scripted reference scorer stands in for the LLM (deterministic base scores); nothing
here says anything about an LLM's quality."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any

import pytest

from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm

EPISODES = 3


async def run(task: str, seed: int, processes: bool, memory_dir: Path) -> dict[str, Any]:
    opts = SwarmOptions(
        task=task, seed=seed, episodes=EPISODES, beta=0.8, selector="scripted",
        processes=processes, memory_dir=memory_dir, deadline_s=10.0,
    )  # fmt: skip
    return (await run_swarm(opts)).as_dict()


def memory_rows(memory_dir: Path) -> dict[str, list[tuple[Any, ...]]]:
    """Every daemon's memory in stored order (what retrieval's tie-break sees), without
    the run identity and wall-clock stamps that differ between runs by design."""
    out = {}
    for path in sorted(memory_dir.glob("*.sqlite3")):
        with sqlite3.connect(f"file:{path}?mode=ro", uri=True) as conn:
            out[path.stem] = conn.execute(
                "SELECT origin, uav, episode, round, skill, invocation, reward, ret, final "
                "FROM records ORDER BY seq"
            ).fetchall()
    return out


@pytest.mark.slow
@pytest.mark.parametrize(("task", "seed"), [("coverage", 3), ("line_formation", 1)])
async def test_beta_runs_give_the_same_returns_in_process_and_in_processes(
    task: str, seed: int, tmp_path: Path
) -> None:
    a = await run(task, seed, False, tmp_path / "in-process")
    b = await run(task, seed, True, tmp_path / "processes")
    assert (a["mode"], b["mode"]) == ("in-process", "processes")
    assert [e["agent_returns"] for e in b["episodes"]] == [
        e["agent_returns"] for e in a["episodes"]
    ]
    assert [e["rounds"] for e in b["episodes"]] == [e["rounds"] for e in a["episodes"]]
    for data in (a, b):
        barrier = data["experience_barrier"]
        assert (barrier["episodes"], barrier["confirmed"], barrier["timeouts"]) == (3, 3, 0)
        assert barrier["records"] > 0  # peers' records really crossed the barrier
        assert data["lost_uavs"] == {}
        assert data["decode_errors"] == 0
    # the memories are the same, record for record, in the same stored order
    mem_a, mem_b = memory_rows(tmp_path / "in-process"), memory_rows(tmp_path / "processes")
    assert mem_a == mem_b
    for uav, rows in mem_a.items():
        peers = [r for r in rows if r[0] != ""]
        assert peers, f"{uav} learnt nothing from its peers"
        # every peer record of episode k was stored before this daemon's own episode k+1
        # decisions, in canonical (episode, uav, round) order
        for k in range(EPISODES - 1):
            first_own_next = next(i for i, r in enumerate(rows) if r[0] == "" and r[2] == k + 1)
            batch = [(r[2], r[1], r[3]) for r in rows if r[0] != "" and r[2] == k]
            positions = [i for i, r in enumerate(rows) if r[0] != "" and r[2] == k]
            assert batch == sorted(batch)
            assert max(positions) < first_own_next, (uav, k)
