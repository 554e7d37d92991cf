"""Real TLS + mTLS + ACL zenoh sessions on loopback, for the security tests.

``SecureNet`` opens secured meshes that find each other (the first one listens on a fixed
port and is the seed). ``raw`` opens a plain zenoh session that presents a certificate but
loads no ACL and signs nothing: a compromised or hostile node's own process, which the
receiving nodes must refuse by themselves.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable
from typing import Any

import zenoh

from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.mesh.session import Mesh, MeshError, zenoh_settings
from aeroweaver_edge.security.identity import SwarmPki
from tests.helpers.zenoh_net import free_port, unique_namespace


class SecureNet:
    def __init__(self, pki: SwarmPki, namespace: str | None = None) -> None:
        self.pki = pki
        self.namespace = namespace if namespace is not None else unique_namespace("sec")
        self.seed_port: int | None = None
        self.meshes: list[Mesh] = []
        self.sessions: list[zenoh.Session] = []

    @property
    def seed(self) -> str:
        assert self.seed_port is not None
        return f"tls/127.0.0.1:{self.seed_port}"

    def config(
        self,
        name: str,
        *,
        seed: bool = False,
        pki: SwarmPki | None = None,
        mode: str = "peer",
        **security: Any,
    ) -> MeshConfig:
        sec = (pki or self.pki).security_for(name).model_copy(update=security)
        listen = [self.seed if seed else "tls/127.0.0.1:0"] if mode != "client" else []
        return MeshConfig.model_validate(
            {
                "mode": mode,
                "listen": listen,
                "connect": [] if seed else [self.seed],
                "namespace": self.namespace or None,
                "security": sec,
            }
        )

    async def open(self, name: str, *, mode: str = "peer", **security: Any) -> Mesh:
        if self.seed_port is None:
            for _ in range(3):  # the free port may be taken between probe and bind
                self.seed_port = free_port()
                try:
                    cfg = self.config(name, seed=True, mode="peer" if mode == "client" else mode)
                    mesh = await Mesh.open(cfg, node_id=name)
                    break
                except MeshError:
                    continue
            else:
                raise MeshError("could not bind a seed port")
        else:
            mesh = await Mesh.open(self.config(name, mode=mode, **security), node_id=name)
        self.meshes.append(mesh)
        return mesh

    async def raw(
        self,
        name: str,
        *,
        cert_from: SwarmPki | None = None,
        trust: SwarmPki | None = None,
        client_cert: bool = True,
        listen: str | None = None,
        connect: bool = True,
        plain_tcp: bool = False,
        overrides: dict[str, Any] | None = None,
    ) -> zenoh.Session:
        """A hostile node: ``name``'s certificate from ``cert_from`` (default: the real
        swarm), trusting ``trust``'s CA, with no ACL and no signatures. Built by hand so it
        can be wrong in ways our own config checks would refuse."""
        ids = (cert_from or self.pki).paths(name)
        ca = (trust or self.pki).ca_cert
        proto = "tcp" if plain_tcp else "tls"
        base = MeshConfig(listen=[], connect=[], namespace=self.namespace or None, insecure=True)
        conf = zenoh.Config()
        settings = [
            *zenoh_settings(base, None),
            ("listen/endpoints", [listen] if listen else []),
            ("connect/endpoints", [self.seed.replace("tls/", f"{proto}/")] if connect else []),
            ("transport/link/tls/root_ca_certificate", str(ca)),
            ("transport/link/tls/listen_certificate", str(ids.tls_cert)),
            ("transport/link/tls/listen_private_key", str(ids.tls_key)),
            ("transport/link/tls/enable_mtls", True),
        ]
        if client_cert:
            settings += [
                ("transport/link/tls/connect_certificate", str(ids.tls_cert)),
                ("transport/link/tls/connect_private_key", str(ids.tls_key)),
            ]
        for path, value in [*settings, *(overrides or {}).items()]:
            conf.insert_json5(path, json.dumps(value))
        session = await asyncio.to_thread(zenoh.open, conf)
        self.sessions.append(session)
        return session

    async def aclose(self) -> None:
        await asyncio.gather(*(m.aclose() for m in self.meshes))
        await asyncio.gather(*(asyncio.to_thread(s.close) for s in self.sessions))


class Tap:
    """Every sample (or liveliness event) a node receives on a key expression, in order, as
    ``(key, payload)`` (liveliness: ``(key, b"+")`` / ``(key, b"-")``). Transport-level:
    what the ACL let through, before any application check."""

    def __init__(self, session: zenoh.Session, key_expr: str, *, liveliness: bool = False):
        self.items: list[tuple[str, bytes]] = []
        self._changed = asyncio.Event()
        loop = asyncio.get_running_loop()

        def on_sample(sample: zenoh.Sample) -> None:
            if liveliness:
                mark = b"+" if sample.kind == zenoh.SampleKind.PUT else b"-"
                item = (str(sample.key_expr), mark)
            else:
                item = (str(sample.key_expr), sample.payload.to_bytes())
            loop.call_soon_threadsafe(self._add, item)

        handler = zenoh.handlers.Callback(on_sample, indirect=False)
        if liveliness:
            session.liveliness().declare_subscriber(key_expr, handler, history=True)
        else:
            session.declare_subscriber(key_expr, handler)

    def _add(self, item: tuple[str, bytes]) -> None:
        self.items.append(item)
        self._changed.set()

    async def wait_for(self, item: tuple[str, bytes], timeout_s: float = 5.0) -> bool:
        """True once ``item`` has been received (bounded wait, no sleeping)."""
        try:
            async with asyncio.timeout(timeout_s):
                while item not in self.items:
                    self._changed.clear()
                    await self._changed.wait()
        except TimeoutError:
            return False
        return True


async def until_delivered(
    tap: Tap, send: Callable[[], None], item: tuple[str, bytes], timeout_s: float = 5.0
) -> bool:
    """Repeat ``send`` until ``tap`` sees ``item``: the link and the subscription are up."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    while loop.time() < deadline:
        send()
        if await tap.wait_for(item, 0.1):
            return True
    return False
