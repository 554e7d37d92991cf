"""A hostile process on a simulated run's loopback network, for the attack suite.

``open_raw`` makes a plain zenoh session that dials the run's router with some identity's
certificate (the run's own: a compromised node; or another CA's: an outsider) and loads no
ACL: whatever it gets away with is what the receiving nodes let through. ``Attacker`` puts
payloads on it, signed with a given identity's key or not at all, exactly as built (a
forged header is sent as forged).
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

import msgspec
import zenoh

from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.contracts.wire import Codec
from aeroweaver_edge.mesh.session import zenoh_settings
from aeroweaver_edge.orchestration.network import RunNetwork
from aeroweaver_edge.security.identity import SwarmPki
from aeroweaver_edge.security.pki import load_signing_key
from aeroweaver_edge.security.signing import Signer

MUST_CONNECT = {"connect/exit_on_failure": True, "connect/timeout_ms": 2000}


async def open_raw(
    net: RunNetwork,
    name: str,
    *,
    cert_from: SwarmPki | None = None,
    trust: SwarmPki | None = None,
) -> zenoh.Session:
    """A client session to the run's router as ``name`` (certificate from ``cert_from``,
    default the run's PKI; trusting ``trust``'s CA, default the run's). Raises
    ``zenoh.ZError`` if no link can be made."""
    assert net.pki is not None, "the attack suite runs against a secured run"
    ids = (cert_from or net.pki).paths(name)
    ca = (trust or net.pki).ca_cert
    base = MeshConfig(mode="client", listen=[], connect=[], namespace=net.namespace)
    settings: list[tuple[str, Any]] = [
        *zenoh_settings(base, None),
        ("connect/endpoints", [net.endpoint]),
        ("transport/link/tls/root_ca_certificate", str(ca)),
        ("transport/link/tls/listen_certificate", str(ids.tls_cert)),
        ("transport/link/tls/listen_private_key", str(ids.tls_key)),
        ("transport/link/tls/connect_certificate", str(ids.tls_cert)),
        ("transport/link/tls/connect_private_key", str(ids.tls_key)),
        ("transport/link/tls/enable_mtls", True),
        *MUST_CONNECT.items(),
    ]
    conf = zenoh.Config()
    for path, value in settings:
        conf.insert_json5(path, json.dumps(value))
    return await asyncio.to_thread(zenoh.open, conf)


class Attacker:
    """Puts on a raw session; ``signer`` signs as that identity (None: unsigned)."""

    def __init__(self, session: zenoh.Session, signer: Signer | None) -> None:
        self.session = session
        self.signer = signer
        self.codec = Codec()
        self.sent = 0

    @classmethod
    async def compromised(cls, net: RunNetwork, name: str) -> Attacker:
        """``name``'s own keys in hostile hands: its certificate and its signing key."""
        assert net.pki is not None
        session = await open_raw(net, name)
        signer = Signer(name, load_signing_key(net.pki.paths(name).sign_key))
        return cls(session, signer)

    def put(self, key: str, msg: msgspec.Struct, *, sign: bool = True) -> None:
        data = self.codec.encode(msg)
        self.put_bytes(key, data, self.signer.sign(key, data) if sign and self.signer else None)

    def put_bytes(self, key: str, data: bytes, attachment: bytes | None) -> None:
        cc = zenoh.CongestionControl.BLOCK
        if attachment is None:
            self.session.put(key, data, congestion_control=cc)
        else:
            self.session.put(key, data, congestion_control=cc, attachment=attachment)
        self.sent += 1

    async def aclose(self) -> None:
        await asyncio.to_thread(self.session.close)
