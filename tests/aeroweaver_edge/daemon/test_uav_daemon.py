"""The daemon over real zenoh sessions: a world runner, a Commander and two daemons
(scripted selector) flying private communication. The daemon takes its role and its task's
routing from the assignment, so the sender's ciphertext reaches the receiver far beyond 55 m
and the world's eavesdropper too; the receiver's guess travels in its command; experience is
stored by keyword; every daemon acknowledges its assignment and ends when the run ends."""

from __future__ import annotations

import asyncio
import uuid

from aeroweaver_edge.agent.memory.experience import ExperienceMemory
from aeroweaver_edge.config import AgentConfig, SimConfig, UavConfig
from aeroweaver_edge.daemon.app import run_daemon
from aeroweaver_edge.daemon.uav_daemon import UavDaemon, routing
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.orchestration.swarm import mesh_configs
from aeroweaver_edge.sim.runner import WorldRunner
from aeroweaver_edge.tasks import create
from commander.commander import Commander
from commander.harness import plan_for_task

SWARM = "dm"


async def test_two_daemons_fly_private_communication(tmp_path: object) -> None:
    seed_cfg, peer_cfg = mesh_configs(f"dm-{uuid.uuid4().hex[:8]}")
    world_mesh = await Mesh.open(seed_cfg, node_id="world")
    cmdr_mesh = await Mesh.open(peer_cfg, node_id="cmdr")
    task = create("private_communication", 2)
    runner = WorldRunner(world_mesh, SWARM, task, SimConfig(uavs=2, seed=3, deadline_s=10.0))
    commander = Commander(cmdr_mesh, SWARM)
    daemons: dict[str, UavDaemon] = {}
    runs: list[asyncio.Task[object]] = []
    try:
        await runner.start()
        await commander.start()
        for uav in task.uav_ids:
            cfg = UavConfig(
                uav=uav, swarm=SWARM, mesh=peer_cfg,
                agent=AgentConfig(selector="scripted", beta=0.0, memory_path=str(
                    tmp_path / f"{uav}.sqlite3")),  # type: ignore[operator]
            )  # fmt: skip
            runs.append(
                asyncio.create_task(run_daemon(cfg, on_ready=lambda d: daemons.update({d.uav: d})))
            )
        assert await runner.wait_alive(task.uav_ids, 30.0) == set()
        plan = plan_for_task("private_communication", task.uav_ids, mission_id="m1")
        commander.publish(plan)
        assert await commander.wait_ready(plan.participants, 30.0) == set()
        result = await runner.run_episode(0)
        runner.shutdown()
        stats = await asyncio.wait_for(asyncio.gather(*runs), 30.0)
    finally:
        for t in runs:
            t.cancel()
        await asyncio.gather(*runs, return_exceptions=True)
        await runner.aclose()
        await commander.aclose()
        await cmdr_mesh.aclose()
        await world_mesh.aclose()

    sender, receiver = task.uav_ids
    assert commander.board.ready == {sender: "sender", receiver: "receiver"}
    # Routing from the assignment: the daemons' inboxes know their role and the task's rule.
    assert daemons[receiver].link.inbox.role == "receiver"  # type: ignore[attr-defined]
    assert routing("private_communication", 55.0)("sender", "receiver", 500.0)
    assert result.rounds == 3
    assert result.metrics["receiver_correct"] == 1.0  # decoded, sent in the command, scored
    key_zero = task.key == 0  # type: ignore[attr-defined]
    assert result.metrics["eavesdropper_correct"] == float(key_zero)  # it heard the broadcast
    s_stats, r_stats = stats
    assert s_stats.rounds == r_stats.rounds == 3  # type: ignore[attr-defined]
    assert s_stats.messages_sent == 3  # type: ignore[attr-defined]
    assert r_stats.deadline_misses == 0  # type: ignore[attr-defined]
    # Every decision was remembered (keyword-built records), on disk.
    assert daemons[receiver].memory is not None
    run = daemons[receiver].memory.run  # type: ignore[union-attr]
    path = tmp_path / f"{receiver}.sqlite3"  # type: ignore[operator]
    with ExperienceMemory(path, run=run) as memory:
        rows = memory.export(receiver, 0, final_only=False)
        assert [(r.round, r.skill) for r in rows] == [
            (0, "hold_position"),
            (1, "decode_message"),
            (2, "decode_message"),
        ]
