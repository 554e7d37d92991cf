"""Swarm identities: who exists, in which role, with which keys, signed by the swarm CA.

A provisioned swarm is one directory (``aeroweaver keys init``), also usable as a
throw-away per-run PKI for ``aeroweaver sim`` and tests (``SwarmPki.create`` in a temp dir
takes a few milliseconds per identity)::

    <root>/ca.crt                  the swarm CA certificate (public; every process has it)
    <root>/ca/ca.key               the CA private key (0600; keep it off the vehicles)
    <root>/identities.json         the identity list, signed by the CA (public)
    <root>/<name>/tls.crt, tls.key this process's TLS certificate (CN = name) and key (0600)
    <root>/<name>/sign.key         this process's Ed25519 message-signing key (0600)
    <root>/state/                  boot counters of the processes that run from this directory

The identity list binds each name to a role and to its Ed25519 public key (and records the
fingerprint of its current TLS certificate). Receivers check message signatures against it
and build the Zenoh ACL from it, so both enforcers agree on the same list.
"""

from __future__ import annotations

import base64
import datetime as dt
import json
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec

from aeroweaver_edge.config import SecurityConfig, check_id
from aeroweaver_edge.security import pki
from aeroweaver_edge.security.key_files import PkiError
from aeroweaver_edge.security.policy import Role

FORMAT = 1
CA_CERT = "ca.crt"
CA_KEY = "ca/ca.key"
IDENTITIES = "identities.json"
STATE = "state"

COMMANDER = "cmdr"
WORLD = "world"
CENTRAL = "central"
OBSERVER = "observer"
OPERATOR = "operator"
ROUTER = "router"


@dataclass(frozen=True)
class Member:
    name: str
    role: Role
    signing_key: bytes  # raw Ed25519 public key, 32 bytes
    tls_cert: str  # fingerprint of the current TLS certificate (informative)

    def as_json(self) -> dict[str, str]:
        return {
            "name": self.name,
            "role": self.role.value,
            "signing_key": base64.b64encode(self.signing_key).decode(),
            "tls_cert": self.tls_cert,
        }


@dataclass(frozen=True)
class IdentityList:
    swarm: str
    version: int
    issued: str
    members: Mapping[str, Member]

    def roles(self) -> dict[str, Role]:
        return {name: m.role for name, m in self.members.items()}

    def body(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "swarm": self.swarm,
            "version": self.version,
            "issued": self.issued,
            "identities": [m.as_json() for _, m in sorted(self.members.items())],
        }

    def signed_document(self, ca: pki.CertifiedKey) -> bytes:
        key = serialization.load_pem_private_key(ca.key_pem, password=None)
        if not isinstance(key, ec.EllipticCurvePrivateKey):
            raise PkiError("the CA key is not an ECDSA key")
        body = self.body()
        signature = key.sign(_canonical(body), ec.ECDSA(hashes.SHA256()))
        doc = {"body": body, "signature": base64.b64encode(signature).decode()}
        return (json.dumps(doc, indent=2, sort_keys=True) + "\n").encode()

    @classmethod
    def parse(cls, data: bytes, ca_cert: x509.Certificate, source: str) -> IdentityList:
        """Read and verify a signed list; any problem is one ``PkiError`` naming ``source``."""
        try:
            doc = json.loads(data)
            body, signature = doc["body"], base64.b64decode(doc["signature"], validate=True)
            pub = ca_cert.public_key()
            if not isinstance(pub, ec.EllipticCurvePublicKey):
                raise PkiError(f"{source}: the CA certificate has no ECDSA key")
            pub.verify(signature, _canonical(body), ec.ECDSA(hashes.SHA256()))
        except InvalidSignature:
            raise PkiError(f"{source}: signature does not verify against the swarm CA") from None
        except (ValueError, KeyError, TypeError) as exc:
            raise PkiError(f"{source}: not a signed identity list ({exc})") from None
        try:
            if body["format"] != FORMAT:
                raise PkiError(f"{source}: format {body['format']}, expected {FORMAT}")
            members: dict[str, Member] = {}
            for item in body["identities"]:
                key = base64.b64decode(item["signing_key"], validate=True)
                if len(key) != 32:
                    raise ValueError(f"{item['name']}: signing key is {len(key)} bytes")
                member = Member(check_id(item["name"], "identity"), Role(item["role"]), key,
                                str(item["tls_cert"]))  # fmt: skip
                members[member.name] = member
            return cls(str(body["swarm"]), int(body["version"]), str(body["issued"]), members)
        except (ValueError, KeyError, TypeError) as exc:
            raise PkiError(f"{source}: malformed identity list ({exc})") from None

    @classmethod
    def load(cls, path: Path, ca_path: Path) -> IdentityList:
        return cls.parse(pki._read(path), pki.load_cert(ca_path), str(path))


def _canonical(body: Any) -> bytes:
    return json.dumps(body, sort_keys=True, separators=(",", ":")).encode()


def default_members(
    uavs: int | Sequence[str],
    *,
    commander: bool = True,
    world: bool = True,
    central: bool = True,
    observer: bool = True,
    router: bool = True,
    operator: bool = True,
) -> dict[str, Role]:
    """The identities of a swarm: ``uav0..uavN-1`` (or the given ids) plus the ground nodes."""
    names = [f"uav{i}" for i in range(uavs)] if isinstance(uavs, int) else list(uavs)
    out = {check_id(n, "uav id"): Role.UAV for n in names}
    extra = {
        COMMANDER: (commander, Role.COMMANDER),
        WORLD: (world, Role.WORLD),
        CENTRAL: (central, Role.CENTRAL),
        OBSERVER: (observer, Role.OBSERVER),
        OPERATOR: (operator, Role.OPERATOR),
        ROUTER: (router, Role.ROUTER),
    }
    for name, (wanted, role) in extra.items():
        if wanted:
            if name in out:
                raise PkiError(f"{name!r} is reserved for the {role.value} identity")
            out[name] = role
    return out


@dataclass(frozen=True)
class IdentityPaths:
    dir: Path
    tls_cert: Path
    tls_key: Path
    sign_key: Path


class SwarmPki:
    """A provisioned swarm directory (see the module docstring)."""

    def __init__(self, root: Path, identities: IdentityList) -> None:
        self.root = root
        self.identities = identities

    @property
    def swarm(self) -> str:
        return self.identities.swarm

    @property
    def ca_cert(self) -> Path:
        return self.root / CA_CERT

    @property
    def identity_list(self) -> Path:
        return self.root / IDENTITIES

    @property
    def state_dir(self) -> Path:
        return self.root / STATE

    def paths(self, name: str) -> IdentityPaths:
        d = self.root / name
        return IdentityPaths(d, d / "tls.crt", d / "tls.key", d / "sign.key")

    # -- making ---------------------------------------------------------------------------

    @classmethod
    def create(
        cls,
        root: Path,
        swarm: str,
        members: Mapping[str, Role],
        *,
        hosts: Iterable[str] = (),
        host_of: Mapping[str, Sequence[str]] | None = None,
        days: int = 30,
        ca_days: int = 365,
        overwrite: bool = False,
    ) -> SwarmPki:
        """Make a CA, every identity's keys and certificate, and the signed list.
        ``hosts`` go into every certificate's SANs, ``host_of[name]`` into one's."""
        check_id(swarm, "swarm id")
        if not members:
            raise PkiError("a swarm needs at least one identity")
        unknown = sorted(set(host_of or {}) - set(members))
        if unknown:
            raise PkiError(f"addresses for unknown identities: {', '.join(unknown)}")
        root = Path(root)
        if (root / CA_CERT).exists() and not overwrite:
            raise PkiError(f"{root}: already holds a swarm PKI (use a new directory)")
        ca = pki.make_ca(swarm, days=ca_days)
        pki.write_file(root / CA_CERT, ca.cert_pem)
        pki.write_file(root / CA_KEY, ca.key_pem, private=True)
        os.chmod(root / "ca", 0o700)
        (root / STATE).mkdir(parents=True, exist_ok=True)
        hosts, host_of = list(hosts), {k: list(v) for k, v in (host_of or {}).items()}
        made = {
            name: _issue_member(root, ca, name, role, _san(hosts, host_of, name), days)
            for name, role in members.items()
        }
        ids = IdentityList(swarm, 1, _stamp(), made)
        pki.write_file(root / IDENTITIES, ids.signed_document(ca))
        _write_meta(root, {"swarm": swarm, "hosts": hosts, "host_of": host_of, "days": days})
        return cls(root, ids)

    @classmethod
    def load(cls, root: Path) -> SwarmPki:
        root = Path(root)
        if not (root / IDENTITIES).exists():
            raise PkiError(f"{root}: no {IDENTITIES} here (run `aeroweaver keys init` first)")
        return cls(root, IdentityList.load(root / IDENTITIES, root / CA_CERT))

    def rotate(self, name: str) -> Member:
        """Re-issue one identity (new TLS key + certificate, new signing key) and re-sign the
        list with a higher version. Distribute ``identities.json`` and the identity's folder;
        other processes pick the list up on their next start."""
        if name not in self.identities.members:
            raise PkiError(
                f"unknown identity {name!r}; known: {', '.join(sorted(self.identities.members))}"
            )
        ca = pki.load_ca(self.root / CA_CERT, self.root / CA_KEY)
        meta = _read_meta(self.root)
        san = _san(meta.get("hosts", []), meta.get("host_of", {}), name)
        role = self.identities.members[name].role
        member = _issue_member(self.root, ca, name, role, san, int(meta.get("days", 30)))
        members = {**self.identities.members, name: member}
        ids = IdentityList(self.swarm, self.identities.version + 1, _stamp(), members)
        pki.write_file(self.root / IDENTITIES, ids.signed_document(ca))
        self.identities = ids
        return member

    # -- using ----------------------------------------------------------------------------

    def security_for(
        self,
        name: str,
        *,
        state_dir: Path | None = None,
        sign: bool = True,
        acl: bool = True,
        verify_name: bool = True,
        install_dir: Path | None = None,
        key_dir: str | None = None,
    ) -> SecurityConfig:
        """The ``[mesh.security]`` section for one process. ``install_dir``: where this
        directory will live on the target machine, if not here. ``key_dir``: where the
        process finds its two private keys instead (``{name}`` is replaced), e.g. systemd's
        ``/run/credentials/aeroweaver-daemon@{name}.service`` with ``LoadCredential=``."""
        if name not in self.identities.members:
            raise PkiError(f"unknown identity {name!r}")
        base = install_dir or self.root.resolve()
        role = self.identities.members[name].role
        signs = role not in (Role.OBSERVER, Role.ROUTER)
        keys = Path(key_dir.replace("{name}", name)) if key_dir else base / name
        return SecurityConfig(
            identity=name,
            ca=str(base / CA_CERT),
            cert=str(base / name / "tls.crt"),
            key=str(keys / "tls.key"),
            signing_key=str(keys / "sign.key") if signs else None,
            identities=str(base / IDENTITIES),
            acl=acl,
            sign=sign,
            verify_name=verify_name,
            state_dir=str(state_dir if state_dir is not None else base / STATE),
        )

    def describe(self) -> list[dict[str, str]]:
        """One row per identity, for ``aeroweaver keys show``."""
        rows = []
        for name, m in sorted(self.identities.members.items()):
            p = self.paths(name)
            row = {
                "name": name,
                "role": m.role.value,
                "signing_key": pki.fingerprint(m.signing_key),
            }
            if p.tls_cert.exists():
                cert = pki.load_cert(p.tls_cert)
                ok = pki.verify_issued_by(cert, pki.load_cert(self.ca_cert))
                row["tls_cert"] = pki.cert_fingerprint(p.tls_cert.read_bytes())
                row["expires"] = cert.not_valid_after_utc.strftime("%Y-%m-%d")
                row["status"] = "ok" if ok and row["tls_cert"] == m.tls_cert else "STALE"
            else:
                row.update(tls_cert=m.tls_cert, expires="-", status="not here")
            rows.append(row)
        return rows


def _san(hosts: Sequence[str], host_of: Mapping[str, Sequence[str]], name: str) -> list[str]:
    return [*pki.DEFAULT_HOSTS, *hosts, *host_of.get(name, ())]


def _issue_member(
    root: Path, ca: pki.CertifiedKey, name: str, role: Role, san: Sequence[str], days: int
) -> Member:
    check_id(name, "identity")
    d = root / name
    tls = pki.issue(ca, name, san, days=days)
    signing = pki.make_signing_key()
    pki.write_file(d / "tls.crt", tls.cert_pem)
    pki.write_file(d / "tls.key", tls.key_pem, private=True)
    pki.write_file(d / "sign.key", pki.signing_key_pem(signing), private=True)
    os.chmod(d, 0o755)  # the certificate is public; the two keys inside are 0600
    return Member(name, role, pki.raw_public(signing), pki.cert_fingerprint(tls.cert_pem))


def _stamp() -> str:
    return dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _write_meta(root: Path, meta: dict[str, Any]) -> None:
    pki.write_file(root / "swarm.json", (json.dumps(meta, indent=2) + "\n").encode())


def _read_meta(root: Path) -> dict[str, Any]:
    try:
        data = json.loads((root / "swarm.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}
