"""``aeroweaver mission start --sim-world`` end to end: daemons already up (scripted
selector), the mission text parsed once against the live roster by the rules, the plan
published, and the kinematic world flying the plan's task with the plan's roles."""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import AsyncIterator

import pytest

from aeroweaver_edge.config import (
    AgentConfig,
    ConfigError,
    MeshConfig,
    SecurityConfig,
    SimConfig,
    UavConfig,
)
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.daemon.app import run_daemon
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.orchestration.mission import MissionStartOptions, start_mission
from aeroweaver_edge.orchestration.swarm import mesh_configs
from aeroweaver_edge.sim.runner import RoundLog, WorldRunner
from aeroweaver_edge.tasks import create
from commander.progress import ProgressBoard

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
    assert out["envelope_violations"]["total"] == 0
    assert out["envelope_violations"]["checked"] == 2 * 3


@pytest.fixture
async def daemons() -> AsyncIterator[tuple[MeshConfig, MeshConfig]]:
    """Three scripted daemons already up; yields (the seed's, a peer's) mesh settings: the
    seed is whoever opens it (the Commander, or the world standing in for the field)."""
    cmdr_cfg, peer_cfg = mesh_configs(f"ms-{uuid.uuid4().hex[:8]}", star=False)
    agent = AgentConfig(selector="scripted", beta=0.0)
    tasks = [
        asyncio.create_task(
            run_daemon(UavConfig(uav=f"uav{i}", swarm=SWARM, mesh=peer_cfg, agent=agent))
        )
        for i in range(3)
    ]
    try:
        yield cmdr_cfg, peer_cfg
    finally:
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


COVER = "Cover the three landmarks with three drones."


async def test_no_daemon_up_is_one_clear_error() -> None:
    cmdr_cfg, _ = mesh_configs(f"ms-{uuid.uuid4().hex[:8]}", star=False)
    opts = MissionStartOptions(text=COVER, swarm="nobody", mesh=cmdr_cfg, roster_wait_s=0.3)
    with pytest.raises(
        UserError,
        match=r"^no UAV daemon of swarm 'nobody' answered within 0.3 s; "
        r"start them",
    ):
        await start_mission(opts)


async def test_a_secured_sim_world_without_the_world_identity_is_refused() -> None:
    """The world must speak as itself on a secured mesh: refused before any session opens
    (nothing listens on the endpoint, so an attempt to open would fail differently)."""
    security = SecurityConfig(
        identity="cmdr", ca="ca.pem", cert="cmdr.pem", key="cmdr.key", identities="ids.json"
    )
    mesh = MeshConfig(listen=["tls/127.0.0.1:9"], security=security)
    opts = MissionStartOptions(text=COVER, mesh=mesh, sim_world=True)
    with pytest.raises(ConfigError, match=r"^a secured mission with the sim world needs the world"):
        await start_mission(opts)


async def test_operator_stop_ends_the_mission_and_reports_it(
    daemons: tuple[MeshConfig, MeshConfig],
) -> None:
    """Ctrl-C (the task cancelled) mid-episode: the mission ends as an operator stop, with
    the progress so far, and the cancellation does not escape."""
    cmdr_cfg, _ = daemons
    rounds: list[int] = []
    me: list[asyncio.Task[dict[str, object]]] = []

    async def on_round(log: RoundLog, board: ProgressBoard) -> None:
        rounds.append(log.round)
        if log.round == 1:
            me[0].cancel()

    opts = MissionStartOptions(
        text=COVER, swarm=SWARM, mesh=cmdr_cfg, roster_wait_s=3.0, sim_world=True
    )
    me.append(asyncio.create_task(start_mission(opts, on_round=on_round)))
    out = await me[0]
    assert out["ended"] == "operator stop"
    assert rounds == [0, 1]
    assert out["episodes"] == []  # the episode never finished
    progress = out["progress"]
    assert isinstance(progress, dict)
    assert set(progress) == {"uav0", "uav1", "uav2"}
    assert all(row["reports"] >= 1 for row in progress.values())  # round 1's may be in flight


async def test_field_mode_watches_until_every_uav_reported_its_rounds(
    daemons: tuple[MeshConfig, MeshConfig],
) -> None:
    """Without ``--sim-world`` the Commander only watches; here a world the test runs on its
    own session stands in for the field and drives the daemons' rounds."""
    seed_cfg, peer_cfg = daemons
    world_mesh = await Mesh.open(seed_cfg, node_id="world")  # the daemons' seed: up first
    task = create("coverage", {f"uav{i}": "searcher" for i in range(3)}, max_rounds=3)
    runner = WorldRunner(world_mesh, SWARM, task, SimConfig(uavs=3, max_rounds=3, deadline_s=10))
    await runner.start()
    try:
        assert await runner.wait_alive(["uav0", "uav1", "uav2"], 20.0) == set()
        opts = MissionStartOptions(text=COVER, swarm=SWARM, mesh=peer_cfg, max_rounds=2)
        mission = asyncio.create_task(start_mission(opts))
        episode = 0
        async with asyncio.timeout(60.0):  # rounds go on until the Commander has seen enough
            while not mission.done():
                await runner.run_episode(episode)
                episode += 1
            out = await mission
    finally:
        await runner.aclose()
        await world_mesh.aclose()
    assert out["ended"] == "horizon"
    assert out["mission"]["task"] == "coverage"  # type: ignore[index]
    progress = out["progress"]
    assert isinstance(progress, dict)
    assert all(row["reports"] >= 2 for row in progress.values())
    # The Commander flew nothing: its one field episode is what the UAVs reported.
    [episode] = out["episodes"]  # type: ignore[misc]
    assert episode["source"] == "field: the UAVs' round reports"
    assert episode["reason"] == "horizon"
    assert episode["decisions"] == sum(row["reports"] for row in progress.values())
    assert episode["rounds"] == max(row["reports"] for row in progress.values())
    assert sum(episode["holds_by_cause"].values()) == episode["holds"]
    # this stand-in world scores the rounds, so every UAV has a return (the field has none)
    assert all(isinstance(r, float) for r in episode["agent_returns"].values()), episode
