"""The phase-2 wiring helpers: a secured world/Commander/UAV mesh in a few lines."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from aeroweaver_edge.config import SafetyConfig
from aeroweaver_edge.contracts.wire import Keys
from aeroweaver_edge.mesh.peers import PeerLink
from aeroweaver_edge.mesh.secured import (
    boot_headers,
    ephemeral_swarm,
    insecure_mesh_configs,
    mesh_configs,
    peer_limits,
)
from aeroweaver_edge.mesh.session import Mesh
from tests.helpers.zenoh_net import free_port, unique_namespace


async def test_ephemeral_swarm_runs_secured_peer_links(tmp_path: Path) -> None:
    uavs = ["uav0", "uav1"]
    pki = ephemeral_swarm(tmp_path / "pki", "sim", uavs)
    cfgs = mesh_configs(pki, ["world", "cmdr", *uavs], port=free_port(), seed="world",
                        namespace=unique_namespace())  # fmt: skip
    keys, meshes, links = Keys("sim"), [], {}
    try:
        for name in ["world", "cmdr", *uavs]:
            meshes.append(await Mesh.open(cfgs[name], node_id=name))
        for mesh in meshes[2:]:
            headers = await asyncio.to_thread(boot_headers, cfgs[mesh.node_id], mesh.node_id)
            assert headers.epoch == 1  # first start of this identity
            link = PeerLink(mesh, keys, mesh.node_id, headers, 55.0,
                            limits=peer_limits(pki, SafetyConfig(), 0.5))  # fmt: skip
            await link.start()
            links[mesh.node_id] = link
        for uav, link in links.items():
            assert await link.wait_for_peers(set(uavs) - {uav}, 5.0)
            link.publish_beacon(1, (0.0, 0.0, -5.0), (0.0, 0.0, 0.0))
        a, b = links["uav0"], links["uav1"]
        ref = await a.send("uav1", "status", {"ok": True}, round=1)
        assert ref is not None
        [msg] = await b.collect_inbox([ref], timeout_s=5.0)
        assert msg.body == {"ok": True}
        assert all(m.security_summary()["signed"] for m in meshes)
        assert b._mesh.authenticated
        assert (tmp_path / "pki" / "state" / "uav0.boot").read_text() == "1\n"
    finally:
        for link in links.values():
            await link.aclose()
        await asyncio.gather(*(m.aclose() for m in meshes))


def test_config_helpers_check_their_input(tmp_path: Path) -> None:
    pki = ephemeral_swarm(tmp_path, "sim", ["uav0"])
    with pytest.raises(ValueError, match="seed 'nobody'"):
        mesh_configs(pki, ["uav0"], port=1, seed="nobody")
    plain = insecure_mesh_configs(["world", "uav0"], port=7, seed="world")
    assert plain["world"].listen == ["tcp/127.0.0.1:7"]
    assert plain["uav0"].connect == ["tcp/127.0.0.1:7"]
    assert plain["uav0"].security is None
    assert boot_headers(plain["uav0"], "uav0").epoch > 10**15  # clock-based fallback
    limits = peer_limits(pki, SafetyConfig(), 0.5)
    assert limits.known_peers == frozenset({"uav0"})
    assert limits.max_speed_mps == 11.0
    assert limits.max_abs_m is not None
    assert 99.0 < limits.max_abs_m < 200.0
    assert peer_limits(None, SafetyConfig(), 0.5).known_peers is None


async def test_a_secured_daemon_runs_on_its_boot_counter_and_the_identity_list(
    tmp_path: Path,
) -> None:
    """What app.py wires for ``aeroweaver daemon`` with [mesh.security]: the header epoch is
    the persisted boot counter, only the swarm's UAVs may join the roster, beacons are held
    to the envelope, and the Commander's authority is its live token."""
    from aeroweaver_edge.config import AgentConfig, UavConfig
    from aeroweaver_edge.daemon.app import run_daemon
    from aeroweaver_edge.daemon.uav_daemon import UavDaemon

    pki = ephemeral_swarm(tmp_path / "pki", "sim", ["uav0", "uav1"])
    cfg = mesh_configs(pki, ["uav0"], port=free_port(), seed="uav0")["uav0"]
    uav = UavConfig(uav="uav0", swarm="sim", mesh=cfg,
                    agent=AgentConfig(selector="scripted", beta=0.0))  # fmt: skip
    for start in (1, 2):  # a restart is the next epoch, whatever the clock says
        ready: asyncio.Future[UavDaemon] = asyncio.get_running_loop().create_future()
        task = asyncio.create_task(run_daemon(uav, on_ready=ready.set_result))
        try:
            d = await asyncio.wait_for(ready, 30.0)
            assert d.headers.epoch == start
            assert d.mission.track_commander
            link = d._peer_link
            assert link is not None
            assert link.limits.known_peers == frozenset({"uav0", "uav1"})
            assert link.limits.max_speed_mps == SafetyConfig().max_speed_mps
            assert d.mesh.authenticated
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
