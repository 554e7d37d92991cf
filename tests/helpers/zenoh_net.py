"""Real zenoh sessions on loopback for tests: one seed plus gossip, one namespace per net.

Every session the net opens is closed by ``aclose`` (concurrently: a close can take up to
~1 s), so a failing test neither leaks sessions nor hangs the interpreter at exit.
"""

from __future__ import annotations

import asyncio
import socket
import uuid
from collections.abc import Callable

from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.contracts.wire import Codec
from aeroweaver_edge.mesh.session import Mesh, MeshError


def free_port() -> int:
    """A TCP port that was free a moment ago (the seed binds it right after)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def unique_namespace(prefix: str = "t") -> str:
    return f"{prefix}-{uuid.uuid4().hex[:10]}"


class ZenohNet:
    """Opens meshes that find each other: the first is the seed, the rest connect to it."""

    def __init__(self, namespace: str | None = None) -> None:
        self.namespace = namespace or unique_namespace()
        self.seed_port: int | None = None
        self.meshes: list[Mesh] = []

    def config(self, *, seed: bool, **overrides: object) -> MeshConfig:
        assert self.seed_port is not None
        endpoint = f"tcp/127.0.0.1:{self.seed_port}"
        return MeshConfig.model_validate(
            {
                "listen": [endpoint if seed else "tcp/127.0.0.1:0"],
                "connect": [] if seed else [endpoint],
                "namespace": self.namespace,
                **overrides,
            }
        )

    async def open(self, node_id: str, codec: Codec | None = None) -> Mesh:
        if self.seed_port is None:
            for _ in range(3):  # the free port may be taken between probe and bind
                self.seed_port = free_port()
                try:
                    mesh = await Mesh.open(self.config(seed=True), node_id=node_id, codec=codec)
                    break
                except MeshError:
                    continue
            else:
                raise MeshError("could not bind a seed port")
        else:
            mesh = await Mesh.open(self.config(seed=False), node_id=node_id, codec=codec)
        self.meshes.append(mesh)
        return mesh

    async def aclose(self) -> None:
        await asyncio.gather(*(m.aclose() for m in self.meshes))


async def eventually(
    predicate: Callable[[], bool], timeout_s: float = 2.0, interval_s: float = 0.01
) -> bool:
    """Poll ``predicate`` until it holds or ``timeout_s`` passes; returns the last result."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    while not predicate():
        if loop.time() >= deadline:
            return False
        await asyncio.sleep(interval_s)
    return True
