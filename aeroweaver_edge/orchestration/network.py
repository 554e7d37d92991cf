"""The loopback network of one simulated run: a star, secured by default.

Every session is a Zenoh client of one router, so each holds one link instead of one per
peer (a full peer mesh is O(N^2) links). How the router is run depends on security:

- secured (the default): a throw-away swarm PKI is made for the run (world, cmdr, the UAVs,
  the reserved central and observer, and the router), every session runs TLS with mutual
  authentication, loads the swarm ACL and signs what it publishes. The router is its own
  session with the ``router`` identity: it relays for everyone, and the ACL it applies per
  hop (by certificate CN) is what keeps each client to its own keys. Making the world the
  router instead would give the world identity relay rights over every key.
- ``--insecure``: plain TCP; the world's session is the router, as before security.

``RunNetwork.config(name)`` is each process's ``[mesh]`` section (its identity's files
included, so ``--processes`` daemons read them from the run's temporary directory).
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.mesh.secured import ephemeral_swarm
from aeroweaver_edge.mesh.session import Mesh, MeshError
from aeroweaver_edge.security.identity import (
    CENTRAL,
    COMMANDER,
    OBSERVER,
    OPERATOR,
    WORLD,
    SwarmPki,
)

ROUTER = "router"


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass(frozen=True)
class RunNetwork:
    """Where every session of a run connects, and with which identity's files."""

    namespace: str
    endpoint: str  # what clients dial (the router's listen endpoint)
    configs: dict[str, MeshConfig]  # per identity name (world, cmdr, uavN, observer, ...)
    pki: SwarmPki | None = None  # the run's throw-away PKI when secured
    router: Mesh | None = None  # the separate router session (secured runs only)

    @property
    def secured(self) -> bool:
        return self.pki is not None

    def config(self, name: str) -> MeshConfig:
        try:
            return self.configs[name]
        except KeyError:
            raise KeyError(f"no mesh config for {name!r} in this run") from None


def insecure_network(namespace: str, names: Sequence[str], *, world: str = "world") -> RunNetwork:
    """Plain TCP on loopback: ``world``'s session is the router, the rest its clients."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    configs = {
        name: MeshConfig(mode="router", listen=[endpoint], namespace=namespace)
        if name == world
        else MeshConfig(mode="client", listen=[], connect=[endpoint], namespace=namespace)
        for name in names
    }
    return RunNetwork(namespace, endpoint, configs)


def secured_configs(
    pki: SwarmPki, names: Sequence[str], *, endpoint: str, namespace: str
) -> dict[str, MeshConfig]:
    """Client configs for ``names`` and the router's (listening on ``endpoint``)."""
    out = {
        ROUTER: MeshConfig(
            mode="router",
            listen=[endpoint],
            namespace=namespace,
            security=pki.security_for(ROUTER),
        )
    }
    for name in names:
        out[name] = MeshConfig(
            mode="client",
            listen=[],
            connect=[endpoint],
            namespace=namespace,
            security=pki.security_for(name),
        )
    return out


@contextlib.asynccontextmanager
async def secured_network(
    root: Path, swarm: str, namespace: str, uav_ids: Sequence[str]
) -> AsyncIterator[RunNetwork]:
    """A throw-away PKI in ``root`` and a running router; the router closes on exit."""
    pki = await asyncio.to_thread(ephemeral_swarm, root, swarm, list(uav_ids))
    names = [WORLD, COMMANDER, CENTRAL, OBSERVER, OPERATOR, *uav_ids]
    router: Mesh | None = None
    for _ in range(3):  # the free port may be taken between probe and bind
        endpoint = f"tls/127.0.0.1:{free_port()}"
        configs = secured_configs(pki, names, endpoint=endpoint, namespace=namespace)
        try:
            router = await Mesh.open(configs[ROUTER], node_id=ROUTER)
            break
        except MeshError:
            continue
    if router is None:
        raise MeshError("could not bind a loopback port for the run's router")
    try:
        yield RunNetwork(namespace, endpoint, configs, pki=pki, router=router)
    finally:
        await router.aclose()


@contextlib.asynccontextmanager
async def run_network(
    secure: bool, root: Path, swarm: str, namespace: str, uav_ids: Sequence[str]
) -> AsyncIterator[RunNetwork]:
    """The network of one run: ``secured_network`` or, with ``secure=False``, plain TCP."""
    if not secure:
        yield insecure_network(namespace, [WORLD, COMMANDER, CENTRAL, OBSERVER, OPERATOR, *uav_ids])
        return
    async with secured_network(root, swarm, namespace, uav_ids) as net:
        yield net


__all__ = ["ROUTER", "RunNetwork", "free_port", "insecure_network", "run_network",
           "secured_network"]  # fmt: skip
