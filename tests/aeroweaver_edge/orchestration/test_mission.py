"""``aeroweaver mission start --sim-world`` end to end: daemons already up (scripted
selector), the mission text parsed once against the live roster by the rules, the plan
published, and the kinematic world flying the plan's task with the plan's roles."""

from __future__ import annotations

import asyncio
import uuid

from aeroweaver_edge.app import run_daemon
from aeroweaver_edge.config import AgentConfig, UavConfig
from aeroweaver_edge.orchestration.mission import MissionStartOptions, start_mission
from aeroweaver_edge.orchestration.swarm import mesh_configs

SWARM = "ms"


async def test_mission_start_runs_the_sim_world_for_the_parsed_task() -> None:
    cmdr_cfg, peer_cfg = mesh_configs(f"ms-{uuid.uuid4().hex[:8]}", star=False)
    daemons = [
        asyncio.create_task(
            run_daemon(
                UavConfig(
                    uav=f"uav{i}",
                    swarm=SWARM,
                    mesh=peer_cfg,
                    agent=AgentConfig(selector="scripted", beta=0.0),
                )
            )
        )
        for i in range(3)
    ]
    try:
        out = await start_mission(
            MissionStartOptions(
                text="Send the secret symbol to the receiver with two drones; the "
                "eavesdropper must not read it.",
                swarm=SWARM,
                mesh=cmdr_cfg,
                roster_wait_s=4.0,
                sim_world=True,
                seed=2,
            )
        )
    finally:
        for t in daemons:
            t.cancel()
        await asyncio.gather(*daemons, return_exceptions=True)
    assert out["roster"] == ["uav0", "uav1", "uav2"]
    mission = out["mission"]
    assert mission["task"] == "private_communication"
    assert mission["parse_source"] == "fallback"
    roles = {u: a["role"] for u, a in mission["assignments"].items()}
    assert roles == {"uav0": "sender", "uav1": "receiver"}  # the third UAV is not needed
    [episode] = out["episodes"]
    assert (episode["rounds"], episode["reason"]) == (3, "complete")
    assert set(episode["agent_returns"]) == {"uav0", "uav1"}
    assert set(episode["scripted_returns"]) == {"eavesdropper0"}
    assert out["ended"] == "complete"
    assert out["not_ready"] == []
