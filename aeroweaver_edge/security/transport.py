"""Turns a ``[mesh.security]`` section into what a Zenoh session needs: TLS with mutual
authentication, the ACL generated from the identity list, and the message signer/verifier.

Everything is checked before the session opens, so a wrong file is one clear line
("tls.crt: CN is uav1, this process is uav0") instead of a silent run where the ACL or the
signature check refuses every message.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aeroweaver_edge.config import SecurityConfig
from aeroweaver_edge.security import pki
from aeroweaver_edge.security.identity import IdentityList
from aeroweaver_edge.security.key_files import PkiError
from aeroweaver_edge.security.policy import Authorizer, Role, build_acl
from aeroweaver_edge.security.signing import MessageAuth, Signer, Verifier


@dataclass(frozen=True)
class LoadedSecurity:
    config: SecurityConfig
    identities: IdentityList
    role: Role
    acl: dict[str, Any] | None
    auth: MessageAuth | None

    @property
    def summary(self) -> dict[str, Any]:
        """For run summaries: what protects this session."""
        return {
            "tls": True,
            "mtls": True,
            "acl": self.acl is not None,
            "signed": self.auth is not None,
            "identity": self.config.identity,
            "role": self.role.value,
            "identities_version": self.identities.version,
        }


def load_security(sec: SecurityConfig, namespace: str | None = None) -> LoadedSecurity:
    """Read and cross-check the key material; raises ``PkiError`` naming the bad file."""
    ca_path, cert_path, key_path = Path(sec.ca), Path(sec.cert), Path(sec.key)
    ca = pki.load_cert(ca_path)
    identities = IdentityList.load(Path(sec.identities), ca_path)
    member = identities.members.get(sec.identity)
    if member is None:
        raise PkiError(
            f"{sec.identities}: no identity {sec.identity!r} in swarm {identities.swarm!r}"
        )
    cert = pki.load_cert(cert_path)
    cn = pki.common_name(cert)
    if cn != sec.identity:
        raise PkiError(f"{cert_path}: certificate CN is {cn!r}, this process is {sec.identity!r}")
    if not pki.verify_issued_by(cert, ca):
        raise PkiError(f"{cert_path}: not issued by the swarm CA {ca_path}")
    if cert.not_valid_after_utc <= dt.datetime.now(dt.UTC):
        raise PkiError(
            f"{cert_path}: expired on {cert.not_valid_after_utc:%Y-%m-%d} (aeroweaver keys rotate)"
        )
    pki.load_tls_key(key_path, cert, cert_path)
    auth = None
    if sec.sign:
        signer = None
        if sec.signing_key is not None:
            key = pki.load_signing_key(Path(sec.signing_key))
            if pki.raw_public(key) != member.signing_key:
                raise PkiError(
                    f"{sec.signing_key}: not the signing key registered for {sec.identity!r} "
                    f"in {sec.identities} (rotated? install the new key or list)"
                )
            signer = Signer(sec.identity, key)
        elif member.role not in (Role.OBSERVER, Role.ROUTER):
            raise PkiError(f"{sec.identity!r} ({member.role.value}) needs signing_key to publish")
        roles = identities.roles()
        auth = MessageAuth(Verifier(identities, Authorizer(identities.swarm, roles)), signer)
    acl = build_acl(identities.swarm, identities.roles(), namespace) if sec.acl else None
    return LoadedSecurity(sec, identities, member.role, acl, auth)


def zenoh_security_settings(loaded: LoadedSecurity) -> list[tuple[str, Any]]:
    """Zenoh config entries: TLS (both directions, mutual) and the ACL."""
    sec = loaded.config
    tls = "transport/link/tls"
    out: list[tuple[str, Any]] = [
        (f"{tls}/root_ca_certificate", sec.ca),
        (f"{tls}/listen_certificate", sec.cert),
        (f"{tls}/listen_private_key", sec.key),
        (f"{tls}/connect_certificate", sec.cert),
        (f"{tls}/connect_private_key", sec.key),
        (f"{tls}/enable_mtls", True),
        (f"{tls}/verify_name_on_connect", sec.verify_name),
        (f"{tls}/close_link_on_expiration", True),
    ]
    if loaded.acl is not None:
        out.append(("access_control", loaded.acl))
    return out
