"""Every task end to end: world + Commander (plan from the task name, per-role activation)
+ daemons over loopback Zenoh, with the scripted reference selector (no LLM).

In-process runs of all nine tasks are pinned to the returns measured for seed 1 (a change in
a task, a skill or a policy shows up here); a few tasks also run one OS process per daemon
and must give the very same returns, rounds and metrics.
"""

from __future__ import annotations

from typing import Any

import pytest

from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm
from aeroweaver_edge.tasks import TASK_NAMES, get_spec

# team mean return, rounds, end of the episode: seed 1, default team, scripted reference
# (re-pinned when the safety gate began keeping separation reciprocally: UAVs slide past
# each other instead of taking the whole gap; bench reference over 5 seeds in docs/testing.md)
PINNED: dict[str, tuple[float, int, str]] = {
    "coverage": (-26.693824461883835, 24, "horizon"),
    "pursuit_evasion": (70.0, 24, "complete"),
    "guided_navigation": (-3.32672923737776, 14, "complete"),
    "private_communication": (4.0, 3, "complete"),
    "circular_formation": (-8.883145188301205, 21, "complete"),
    "line_formation": (-7.449791114886901, 15, "complete"),
    "world_communication": (29.16124831296148, 24, "horizon"),
    "collection_delivery": (13.678092992947999, 24, "horizon"),
    "goal_concealment": (0.09518363368891022, 24, "horizon"),
}


async def run(task: str, processes: bool) -> dict[str, Any]:
    opts = SwarmOptions(
        task=task, selector="scripted", seed=1, deadline_s=10.0, processes=processes
    )
    return (await run_swarm(opts)).as_dict()


def check(task: str, data: dict[str, Any]) -> None:
    spec = get_spec(task)
    assert data["task"] == task
    assert data["uavs"] == spec.team_size
    assert data["deadline_misses"] == 0
    assert data["decode_errors"] == 0
    assert data["lost_uavs"] == {}
    assert data["mission"]["parse_source"] == "template"  # planned from the task name
    roles = {a["role"] for a in data["mission"]["assignments"].values()}
    assert roles == {r for r, c in spec.role_counts(spec.team_size).items() if c}
    scripted = {b: r for b, r in data["roles"].items() if r in spec.scripted_names}
    assert set(data["scripted_returns"]) == set(scripted)  # reported, not in the team mean
    assert "not an LLM" in data["note"]


@pytest.mark.parametrize("task", TASK_NAMES)
async def test_every_task_runs_in_process_with_its_reference_policy(task: str) -> None:
    data = await run(task, processes=False)
    check(task, data)
    team, rounds, end = PINNED[task]
    assert data["team_return"] == pytest.approx(team, rel=1e-9, abs=1e-9)
    assert data["rounds"] == rounds
    assert data["episodes"][0]["reason"] == end


@pytest.mark.slow
@pytest.mark.parametrize(
    "task", ["private_communication", "guided_navigation", "world_communication", "coverage"]
)
async def test_processes_give_the_same_returns_as_in_process(task: str) -> None:
    a = await run(task, processes=False)
    b = await run(task, processes=True)
    check(task, b)
    assert b["mode"] == "processes"
    assert b["agent_returns"] == a["agent_returns"]
    assert b["scripted_returns"] == a["scripted_returns"]
    assert b["rounds"] == a["rounds"]
    assert b["episodes"][0]["metrics"] == a["episodes"][0]["metrics"]
    assert b["deliveries"] == a["deliveries"]
