"""Shared swarm memory inside an episode (``share_every="round"``), over real Zenoh: a
record a UAV made in round t is stored by every same-role peer at the start of round t+1
-- after that peer's own round-t record, before its round-t+1 decision, never another
role's -- and the run is the same record for record in-process and with one process per
daemon. The scripted reference scorer stands in for the LLM (deterministic base scores)."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any, Literal

import pytest

from aeroweaver_edge.orchestration.daemons import DaemonSet
from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm
from aeroweaver_edge.sim.runner import RoundLog

TASK, SEED, EPISODES = "collection_delivery", 3, 2  # two roles of two collectors, two depots


async def run(
    processes: bool, memory_dir: Path, share_every: Literal["episode", "round"] = "round"
) -> dict[str, Any]:
    opts = SwarmOptions(
        task=TASK, seed=SEED, episodes=EPISODES, beta=0.8, selector="scripted",
        processes=processes, memory_dir=memory_dir, deadline_s=10.0, share_every=share_every,
    )  # fmt: skip
    return (await run_swarm(opts)).as_dict()


def memory_rows(memory_dir: Path) -> dict[str, list[tuple[Any, ...]]]:
    out = {}
    for path in sorted(memory_dir.glob("*.sqlite3")):
        with sqlite3.connect(f"file:{path}?mode=ro", uri=True) as conn:
            out[path.stem] = conn.execute(
                "SELECT origin, uav, role, episode, round, skill, invocation, reward, ret, final "
                "FROM records ORDER BY seq"
            ).fetchall()
    return out


def check_visible_next_round(rows: dict[str, list[tuple[Any, ...]]]) -> int:
    """Every peer record (episode e, round t) sits between the owner's own records of
    (e, t) and (e, t + 1); returns how many peer records were checked."""
    checked = 0
    for uav, mine in rows.items():
        position = {(r[3], r[4]): i for i, r in enumerate(mine) if r[0] == ""}
        roles = {r[2] for r in mine if r[0] == ""}
        for i, r in enumerate(mine):
            if r[0] == "":
                continue
            assert r[2] in roles, f"{uav} stored a record of role {r[2]}"
            e, t = r[3], r[4]
            assert position[(e, t)] < i, (uav, r)  # not earlier than round t+1
            if (e, t + 1) in position:
                assert i < position[(e, t + 1)], (uav, r)  # not later than round t+1
            checked += 1
    return checked


async def test_a_record_of_round_t_reaches_same_role_peers_in_round_t_plus_1(
    tmp_path: Path,
) -> None:
    data = await run(False, tmp_path / "round")
    assert data["decode_errors"] == 0
    assert data["lost_uavs"] == {}
    assert data["experience_barrier"]["timeouts"] == 0
    rows = memory_rows(tmp_path / "round")
    assert check_visible_next_round(rows) > 0
    # both collectors learn from each other; a depot has no same-role peer: only its own
    collectors = [u for u, mine in rows.items() if any(r[2] == "collector" for r in mine)]
    assert len(collectors) == 2
    for u in collectors:
        assert any(r[0] != "" for r in rows[u]), f"{u} learnt nothing from its peer"
    for u, mine in rows.items():
        if u not in collectors:
            assert all(r[0] == "" for r in mine)
    # shared only between episodes, the same peer records come after the whole episode
    await run(False, tmp_path / "episode", share_every="episode")
    for uav, mine in memory_rows(tmp_path / "episode").items():
        last_own_0 = max(i for i, r in enumerate(mine) if r[0] == "" and r[3] == 0)
        first_peer_0 = min((i for i, r in enumerate(mine) if r[0] != "" and r[3] == 0), default=-1)
        assert first_peer_0 in (-1, last_own_0 + 1), uav


@pytest.mark.slow
async def test_round_sharing_gives_the_same_run_in_process_and_in_processes(
    tmp_path: Path,
) -> None:
    a = await run(False, tmp_path / "in-process")
    b = await run(True, tmp_path / "processes")
    assert (a["mode"], b["mode"]) == ("in-process", "processes")
    assert [e["agent_returns"] for e in b["episodes"]] == [
        e["agent_returns"] for e in a["episodes"]
    ]
    for data in (a, b):
        barrier = data["experience_barrier"]
        assert (barrier["episodes"], barrier["confirmed"], barrier["timeouts"]) == (2, 2, 0)
        assert data["lost_uavs"] == {}
    mem_a, mem_b = memory_rows(tmp_path / "in-process"), memory_rows(tmp_path / "processes")
    assert mem_a == mem_b
    assert check_visible_next_round(mem_b) > 0


async def test_a_restarted_daemon_that_lost_its_memory_fetches_its_roles_experience(
    tmp_path: Path,
) -> None:
    """uav1 dies in round KILL_AT of episode 0 with its memory file gone; its new life
    stores its peers' records of the earlier rounds before its own first decision, which
    only the fetch from their queryables can give it (the episode-end export comes later)."""
    kill_at, memory_dir = 8, tmp_path / "mem"

    async def fault(log_: RoundLog, daemons: DaemonSet) -> None:
        if (log_.episode, log_.round) == (0, kill_at):
            await daemons.kill("uav1")
            for path in memory_dir.glob("uav1.sqlite3*"):
                path.unlink()
            await daemons.restart("uav1")

    opts = SwarmOptions(
        task="coverage", seed=2, episodes=1, beta=0.8, selector="scripted",
        memory_dir=memory_dir, deadline_s=10.0, share_every="round",
    )  # fmt: skip
    data = (await run_swarm(opts, fault=fault)).as_dict()
    assert data["decode_errors"] == 0
    mine = memory_rows(memory_dir)["uav1"]
    first_own = min(i for i, r in enumerate(mine) if r[0] == "")
    assert mine[first_own][4] > kill_at  # the new life's first decision
    early = [r for r in mine[:first_own] if r[0] != "" and r[4] < kill_at]
    assert {r[0] for r in early} == {"uav0", "uav2"}, mine[:first_own]
