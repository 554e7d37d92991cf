"""Frames for every task: the world's round snapshot fits one payload at the largest swarm,
the observer turns a live run of each of the nine tasks into frames with bodies, entities
and every UAV's decision, and the frame store joins late and early reports exactly."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from aeroweaver_edge.config import MAX_UAVS, SimConfig
from aeroweaver_edge.console.frames import FrameStore
from aeroweaver_edge.console.observer import SwarmObserver
from aeroweaver_edge.contracts.wire import MAX_PAYLOAD_BYTES, Codec, Header, MsgRef, WorldSnapshot
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.orchestration.planning import uav_ids
from aeroweaver_edge.orchestration.swarm import SwarmHandle, SwarmOptions, run_swarm, world_task
from aeroweaver_edge.tasks import TASK_NAMES
from commander.harness import plan_for_task


def largest(task: str) -> int:
    return 2 if task == "private_communication" else MAX_UAVS  # that task is exactly 2


@pytest.mark.parametrize("task", TASK_NAMES)
def test_a_round_snapshot_fits_one_payload_at_the_largest_swarm(task: str) -> None:
    n = largest(task)
    definition = world_task(plan_for_task(task, uav_ids(n)), 24)
    world = definition.build_world(np.random.default_rng(1), SimConfig(task=task, uavs=n))
    bodies = [b.as_entity() for b in world.bodies()]
    snap = WorldSnapshot(
        h=Header(sender="world", epoch=1, seq=1, stamp=0.0), task=task, episode=0, round=23,
        uavs=definition.uav_ids, bodies=bodies, entities=list(world.entities()),
        rewards={b.id: -1.234567 for b in bodies}, held=definition.uav_ids,
        messages=[MsgRef(sender=u, seq=99, to="*") for u in definition.uav_ids],
    )  # fmt: skip
    size = len(Codec().encode(snap))
    assert size < MAX_PAYLOAD_BYTES // 2, size  # room to spare for the busiest round


def frame(episode: int, rnd: int) -> dict[str, object]:
    return {"episode": episode, "round": rnd, "decisions": {}}


async def test_store_joins_early_and_late_decisions_and_stays_bounded() -> None:
    store = FrameStore(max_frames=3)
    store.add_decision(0, 0, "uav0", {"chosen": "A"})  # before its round's snapshot
    assert store.add_frame(frame(0, 0)) == 0
    early = {"uav0": {"chosen": "A"}}
    assert store.frame(0) == {"episode": 0, "round": 0, "i": 0, "decisions": early}
    assert store.patch_seq == 0  # it came early: part of the frame, no patch
    store.add_decision(0, 0, "uav1", {"chosen": "B"})  # after it: a patch
    assert store.patches_since(0) == {0: {"uav1": {"chosen": "B"}}}
    assert store.add_frame(frame(0, 0)) == 0  # a duplicate snapshot changes nothing
    for r in range(1, 5):
        store.add_frame(frame(0, r))
    assert store.first == 2
    assert [f["round"] for f in store.since(0)] == [2, 3, 4]
    assert store.frame(1) is None
    store.add_decision(0, 1, "uav0", {"chosen": "C"})  # its frame was dropped: kept nowhere
    assert store.patches_since(1) == {}
    woke = asyncio.create_task(store.wait_change(5.0))
    await asyncio.sleep(0)
    store.add_frame(frame(1, 0))
    await asyncio.wait_for(woke, 1.0)


@pytest.mark.slow
@pytest.mark.parametrize("task", TASK_NAMES)
async def test_the_observer_follows_every_task(task: str) -> None:
    store = FrameStore()
    meshes: list[Mesh] = []
    observers: list[SwarmObserver] = []

    async def started(h: SwarmHandle) -> None:
        mesh = await Mesh.open(h.mesh_for("observer"), node_id="observer")
        meshes.append(mesh)
        obs = SwarmObserver(mesh, h.swarm, store)
        await obs.start()
        observers.append(obs)

    try:
        summary = await run_swarm(
            SwarmOptions(task=task, selector="scripted", max_rounds=3), on_started=started
        )
        async with asyncio.timeout(10):  # the last reports may trail the last snapshot
            while not all(len(f["decisions"]) == summary.uavs for f in store.since(0)):
                await store.wait_change(1.0)
    finally:
        for obs in observers:
            await obs.aclose()
        for mesh in meshes:
            await mesh.aclose()
    frames = store.since(0)
    assert [f["round"] for f in frames] == list(range(summary.as_dict()["rounds"]))
    ours = sorted(summary.as_dict()["agent_returns"])
    for f in frames:
        assert f["uavs"] == ours
        assert {b["id"] for b in f["bodies"]} >= set(ours)
        assert f["task"] == task
    theirs = set(summary.as_dict()["scripted_returns"])
    assert {b["id"] for b in frames[0]["bodies"]} == set(ours) | theirs
    assert store.meta["task"] == task
    assert store.meta["mission"]["task"] == task
    assert sorted(store.meta["roles"]) == ours
