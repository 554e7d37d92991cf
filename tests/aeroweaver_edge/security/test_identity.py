"""The swarm PKI: certificates, key files, the signed identity list, rotation, load checks."""

from __future__ import annotations

import json
import stat
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID

from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.mesh.session import load_mesh_security
from aeroweaver_edge.security import pki
from aeroweaver_edge.security.identity import IdentityList, SwarmPki, default_members
from aeroweaver_edge.security.key_files import PkiError
from aeroweaver_edge.security.policy import Role
from aeroweaver_edge.security.transport import load_security


def test_default_members_cover_every_role() -> None:
    assert default_members(2) == {
        "uav0": Role.UAV,
        "uav1": Role.UAV,
        "cmdr": Role.COMMANDER,
        "world": Role.WORLD,
        "central": Role.CENTRAL,
        "observer": Role.OBSERVER,
        "router": Role.ROUTER,
        "operator": Role.OPERATOR,
    }
    assert set(
        default_members(["a1"], central=False, observer=False, router=False, operator=False)
    ) == {
        "a1", "cmdr", "world",
    }  # fmt: skip
    with pytest.raises(PkiError, match="reserved"):
        default_members(["cmdr"])
    with pytest.raises(ValueError, match="uav id"):
        default_members(["UAV 1"])


def test_certificates_fit_mutual_tls(swarm_pki: SwarmPki) -> None:
    ca = pki.load_cert(swarm_pki.ca_cert)
    for name in swarm_pki.identities.members:
        cert = pki.load_cert(swarm_pki.paths(name).tls_cert)
        assert pki.common_name(cert) == name
        assert pki.verify_issued_by(cert, ca)
        eku = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
        assert set(eku) == {ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH}
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        assert "localhost" in san.get_values_for_type(x509.DNSName)
        assert {str(ip) for ip in san.get_values_for_type(x509.IPAddress)} >= {"127.0.0.1"}
        assert not cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
        assert isinstance(cert.public_key(), ec.EllipticCurvePublicKey)
    basic = ca.extensions.get_extension_for_class(x509.BasicConstraints).value
    assert (basic.ca, basic.path_length) == (True, 0)


def test_private_keys_are_owner_only(swarm_pki: SwarmPki) -> None:
    private = [swarm_pki.root / "ca" / "ca.key"]
    for name in swarm_pki.identities.members:
        p = swarm_pki.paths(name)
        private += [p.tls_key, p.sign_key]
        assert stat.S_IMODE(p.dir.stat().st_mode) == 0o755  # a service user reads the cert
    for path in private:
        assert stat.S_IMODE(path.stat().st_mode) == 0o600, path
    assert stat.S_IMODE(swarm_pki.ca_cert.stat().st_mode) == 0o644
    assert stat.S_IMODE((swarm_pki.root / "ca").stat().st_mode) == 0o700
    assert not list(swarm_pki.root.rglob(".*"))  # no temp files left behind


def test_per_identity_addresses_and_refusals(tmp_path: Path) -> None:
    p = SwarmPki.create(tmp_path / "a", "s", default_members(2), hosts=["10.0.0.1"],
                        host_of={"uav1": ["uav1.local", "10.0.0.11"]})  # fmt: skip

    def sans(name: str) -> set[str]:
        cert = pki.load_cert(p.paths(name).tls_cert)
        ext = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        return {str(v) for v in ext.get_values_for_type(x509.IPAddress)} | set(
            ext.get_values_for_type(x509.DNSName)
        )

    assert {"10.0.0.1", "10.0.0.11", "uav1.local"} <= sans("uav1")
    assert "10.0.0.11" not in sans("uav0")
    assert "10.0.0.1" in sans("uav0")
    assert [r["status"] for r in p.describe()] == ["ok"] * 8
    with pytest.raises(PkiError, match="already holds"):
        SwarmPki.create(tmp_path / "a", "s", default_members(1))
    with pytest.raises(PkiError, match="unknown identities: uav9"):
        SwarmPki.create(tmp_path / "b", "s", default_members(1), host_of={"uav9": ["x"]})
    with pytest.raises(ValueError, match="swarm id"):
        SwarmPki.create(tmp_path / "c", "Bad Swarm", default_members(1))


def test_identity_list_is_signed_by_the_ca(swarm_pki: SwarmPki, rogue_pki: SwarmPki) -> None:
    ids = IdentityList.load(swarm_pki.identity_list, swarm_pki.ca_cert)
    assert ids.roles() == default_members(3)
    with pytest.raises(PkiError, match="does not verify"):
        IdentityList.load(swarm_pki.identity_list, rogue_pki.ca_cert)


@pytest.mark.parametrize(
    "edit",
    ["role", "signing_key", "add", "signature", "truncate"],
)
def test_tampered_identity_list_is_refused(swarm_pki: SwarmPki, tmp_path: Path, edit: str) -> None:
    doc = json.loads(swarm_pki.identity_list.read_text())
    members = doc["body"]["identities"]
    if edit == "role":
        members[0]["role"] = "commander"  # promote central to Commander
    elif edit == "signing_key":
        members[-1]["signing_key"] = members[0]["signing_key"]
    elif edit == "add":
        members.append(dict(members[-1], name="uav9"))
    elif edit == "signature":
        doc["signature"] = doc["signature"][:-4] + "AAA="
    path = tmp_path / "identities.json"
    text = json.dumps(doc)
    path.write_text(text[: len(text) // 2] if edit == "truncate" else text)
    with pytest.raises(PkiError, match=str(path)):
        IdentityList.load(path, swarm_pki.ca_cert)


def test_rotation_reissues_one_identity(tmp_path: Path) -> None:
    p = SwarmPki.create(tmp_path, "s", default_members(2))
    before = dict(p.identities.members)
    old_sec = p.security_for("uav1")
    old_key = p.paths("uav1").sign_key.read_bytes()
    member = p.rotate("uav1")
    assert p.identities.version == 2
    assert member.signing_key != before["uav1"].signing_key
    assert member.tls_cert != before["uav1"].tls_cert
    assert p.paths("uav1").sign_key.read_bytes() != old_key
    assert {n: m for n, m in p.identities.members.items() if n != "uav1"} == {
        n: m for n, m in before.items() if n != "uav1"
    }
    assert SwarmPki.load(tmp_path).identities == p.identities  # the list on disk is re-signed
    load_security(old_sec)  # the paths are the same; the new files load cleanly
    with pytest.raises(PkiError, match="unknown identity 'uav7'"):
        p.rotate("uav7")


def test_a_process_with_a_stale_signing_key_is_refused(tmp_path: Path) -> None:
    """After a rotation, a machine that got the new list but kept its old key must not
    start signing traffic every receiver would refuse."""
    p = SwarmPki.create(tmp_path / "p", "s", default_members(1))
    stale = tmp_path / "old-sign.key"
    stale.write_bytes(p.paths("uav0").sign_key.read_bytes())
    stale.chmod(0o600)  # a private key others can read is refused before anything else
    p.rotate("uav0")
    sec = p.security_for("uav0").model_copy(update={"signing_key": str(stale)})
    with pytest.raises(PkiError, match="not the signing key registered"):
        load_security(sec)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"identity": "uav1"}, "certificate CN is 'uav0', this process is 'uav1'"),
        ({"identity": "uav9"}, "no identity 'uav9'"),
        ({"cert": "MISSING"}, "cannot read"),
        ({"key": "MISSING"}, "cannot read the TLS private key"),
        ({"signing_key": None}, "needs signing_key"),
        ({"ca": "ROGUE"}, "does not verify against the swarm CA"),
        ({"cert": "ROGUE_CERT"}, "not issued by the swarm CA"),
        ({"identities": "CA_AS_LIST"}, "not a signed identity list"),
    ],
)
def test_bad_security_section_is_one_clear_error(
    swarm_pki: SwarmPki, rogue_pki: SwarmPki, change: dict[str, object], message: str
) -> None:
    subst = {
        "MISSING": str(swarm_pki.root / "nope.pem"),
        "ROGUE": str(rogue_pki.ca_cert),
        "ROGUE_CERT": str(rogue_pki.paths("uav0").tls_cert),
        "CA_AS_LIST": str(swarm_pki.ca_cert),
    }
    update = {k: subst.get(v, v) if isinstance(v, str) else v for k, v in change.items()}
    sec = swarm_pki.security_for("uav0").model_copy(update=update)
    cfg = MeshConfig(listen=["tls/127.0.0.1:0"], security=sec)
    with pytest.raises(ValueError, match=message.replace("(", r"\(")) as info:
        load_mesh_security(cfg)
    assert str(info.value).startswith("mesh.security: ")
    assert "\n" not in str(info.value)


def test_observer_and_router_need_no_signing_key(swarm_pki: SwarmPki) -> None:
    for name in ("observer", "router"):
        sec = swarm_pki.security_for(name)
        assert sec.signing_key is None
        loaded = load_security(sec)
        assert loaded.auth is not None
        assert loaded.auth.signer is None  # verifies what it receives, signs nothing


def test_expired_certificate_is_refused(tmp_path: Path) -> None:
    p = SwarmPki.create(tmp_path, "s", default_members(1), days=0)
    with pytest.raises(PkiError, match="expired"):
        load_security(p.security_for("uav0"))
