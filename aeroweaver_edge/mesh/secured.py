"""What an orchestrator needs to run a secured swarm (``aeroweaver sim``, tests, bench).

One call per concern, so wiring security into a run is a handful of lines::

    pki = ephemeral_swarm(tmp / "pki", swarm, uav_ids)           # ~30 ms for 3 UAVs
    cfgs = mesh_configs(pki, ["world", "cmdr", *uav_ids], port=free_port(),
                        namespace=ns, seed="world")                # name -> MeshConfig
    mesh = await Mesh.open(cfgs["uav0"], node_id="uav0")           # TLS + ACL + signing
    headers = await asyncio.to_thread(boot_headers, cfgs["uav0"], "uav0")
    link = PeerLink(mesh, keys, "uav0", headers, radius,
                    peer_limits(pki, safety, round_s))
    mission = MissionState("uav0", track_commander=True)           # + liveliness wiring

``insecure_mesh_configs`` gives the same shape for ``--insecure`` (plain loopback TCP).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from aeroweaver_edge.config import MeshConfig, SafetyConfig
from aeroweaver_edge.contracts.wire import HeaderFactory
from aeroweaver_edge.mesh.peers import PeerLimits
from aeroweaver_edge.security.boot import MAX_EPOCH_STEP, next_epoch
from aeroweaver_edge.security.identity import IdentityList, SwarmPki, default_members
from aeroweaver_edge.security.policy import Role


def ephemeral_swarm(root: Path, swarm: str, uav_ids: Sequence[str]) -> SwarmPki:
    """A throw-away PKI for one run: every role, certificates valid for one day."""
    return SwarmPki.create(root, swarm, default_members(uav_ids), days=1, ca_days=1)


def mesh_configs(
    pki: SwarmPki,
    names: Sequence[str],
    *,
    port: int,
    seed: str,
    namespace: str | None = None,
    host: str = "127.0.0.1",
    **mesh: object,
) -> dict[str, MeshConfig]:
    """Secured configs: ``seed`` listens on ``tls/host:port``, the others listen on an
    ephemeral port, dial the seed and find each other by gossip (docs/notes/zenoh.md)."""
    if seed not in names:
        raise ValueError(f"the seed {seed!r} is not among {list(names)}")
    endpoint = f"tls/{host}:{port}"
    out = {}
    for name in names:
        is_seed = name == seed
        out[name] = MeshConfig.model_validate(
            {
                "listen": [endpoint if is_seed else f"tls/{host}:0"],
                "connect": [] if is_seed else [endpoint],
                "namespace": namespace,
                "security": pki.security_for(name),
                **mesh,
            }
        )
    return out


def insecure_mesh_configs(
    names: Sequence[str], *, port: int, seed: str, namespace: str | None = None, **mesh: object
) -> dict[str, MeshConfig]:
    """The same shape without TLS, ACL or signatures (``--insecure``; loopback only)."""
    endpoint = f"tcp/127.0.0.1:{port}"
    return {
        name: MeshConfig.model_validate(
            {
                "listen": [endpoint if name == seed else "tcp/127.0.0.1:0"],
                "connect": [] if name == seed else [endpoint],
                "namespace": namespace,
                **mesh,
            }
        )
        for name in names
    }


def boot_headers(cfg: MeshConfig, name: str) -> HeaderFactory:
    """Headers whose epoch is this process's persisted boot counter when the config has a
    state directory (blocking file IO: call it in a worker thread), else the old
    clock-based epoch."""
    sec = cfg.security
    if sec is not None and sec.state_dir is not None:
        return HeaderFactory(name, epoch=next_epoch(sec.state_dir, name))
    return HeaderFactory(name)


def peer_limits(
    pki: SwarmPki | IdentityList | None,
    safety: SafetyConfig,
    round_s: float,
    *,
    margin_m: float = 5.0,
) -> PeerLimits:
    """PeerLink bounds for a swarm: only its UAVs (from the identity list, when secured)
    join rosters; beacons must fit the vehicles' speed and the geofence (plus margin);
    boot-counter epochs bound leaps. Without identities the roster stays open."""
    north, east = safety.geofence_north_m, safety.geofence_east_m
    corner = max(abs(north[0]), abs(north[1])) ** 2 + max(abs(east[0]), abs(east[1])) ** 2
    known = None
    ids = pki.identities if isinstance(pki, SwarmPki) else pki
    if ids is not None:
        known = frozenset(n for n, r in ids.roles().items() if r is Role.UAV)
    return PeerLimits(
        known_peers=known,
        max_speed_mps=safety.max_speed_mps,
        round_s=round_s,
        motion_margin_m=margin_m,
        max_abs_m=corner**0.5 + safety.altitude_band_m[1] + margin_m,
        max_epoch_step=MAX_EPOCH_STEP if ids is not None else None,
    )
