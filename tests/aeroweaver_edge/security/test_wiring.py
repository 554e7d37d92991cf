"""The phase-2 wiring helpers: a secured world/Commander/UAV mesh in a few lines."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from aeroweaver_edge.config import SafetyConfig
from aeroweaver_edge.mesh import Mesh
from aeroweaver_edge.peers import PeerLink
from aeroweaver_edge.security.wiring import (
    boot_headers,
    ephemeral_swarm,
    insecure_mesh_configs,
    mesh_configs,
    peer_limits,
)
from aeroweaver_edge.wire import Keys
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
