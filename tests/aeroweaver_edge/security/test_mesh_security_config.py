"""``[mesh]`` + ``[mesh.security]`` validation: a field config never listens without TLS."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from aeroweaver_edge.config import (
    ConfigError,
    MeshConfig,
    UavConfig,
    endpoint_is_loopback,
    load_config,
)
from aeroweaver_edge.mesh.session import build_zenoh_config
from aeroweaver_edge.security.identity import SwarmPki


@pytest.mark.parametrize(
    ("endpoint", "loopback"),
    [
        ("tcp/127.0.0.1:7447", True),
        ("tcp/127.8.0.1:7447", True),
        ("tcp/[::1]:7447", True),
        ("tcp/localhost:7447", True),
        ("udp/127.0.0.1:7447#iface=lo", True),
        ("unixsock-stream//tmp/zenoh.sock", True),
        ("tcp/0.0.0.0:7447", False),
        ("tcp/[::]:7447", False),
        ("tcp/10.0.0.1:7447", False),
        ("tcp/uav1.local:7447", False),
        ("ws/192.168.1.4:80", False),
        ("tcp/garbage", False),
    ],
)
def test_loopback_endpoints(endpoint: str, loopback: bool) -> None:
    assert endpoint_is_loopback(endpoint) is loopback


def bad(**fields: object) -> str:
    with pytest.raises(ValueError, match="validation error") as info:
        MeshConfig.model_validate(fields)
    return str(info.value)


def test_plain_links_off_this_machine_need_insecure() -> None:
    assert "plain link off this machine" in bad(listen=["tcp/0.0.0.0:7447"])
    assert "connect[0]" in bad(connect=["tcp/10.0.0.1:7447"])
    ok = MeshConfig(listen=["tcp/0.0.0.0:7447"], insecure=True)
    assert ok.insecure
    MeshConfig(listen=["tcp/127.0.0.1:0"], connect=["tcp/127.0.0.1:7447"])  # CI default


def test_tls_needs_the_security_section_and_vice_versa(swarm_pki: SwarmPki) -> None:
    assert "needs [mesh.security]" in bad(listen=["tls/0.0.0.0:7447"])
    sec = swarm_pki.security_for("uav0").model_dump()
    assert "every endpoint is tls/" in bad(listen=["tcp/127.0.0.1:0"], security=sec)
    assert "every endpoint is tls/" in bad(
        listen=["tls/127.0.0.1:0"], connect=["tcp/127.0.0.1:1"], security=sec, insecure=True
    )
    MeshConfig(listen=["tls/0.0.0.0:7447"], connect=["quic/10.0.0.2:7447"], security=sec)


@pytest.mark.parametrize(
    "path", ["transport/link/tls/enable_mtls", "access_control/enabled", "/transport/auth/usrpwd"]
)
def test_overrides_cannot_undo_security(swarm_pki: SwarmPki, path: str) -> None:
    sec = swarm_pki.security_for("uav0").model_dump()
    msg = bad(listen=["tls/127.0.0.1:0"], security=sec, zenoh_overrides={path: "false"})
    assert "set by [mesh.security]" in msg


def test_secured_zenoh_config_has_mutual_tls_and_the_acl(swarm_pki: SwarmPki) -> None:
    cfg = MeshConfig(
        listen=["tls/127.0.0.1:0"], namespace="ns", security=swarm_pki.security_for("uav1")
    )
    conf = build_zenoh_config(cfg)

    def get(path: str) -> object:
        return json.loads(conf.get_json(path))

    assert get("transport/link/tls/enable_mtls") is True
    assert get("transport/link/tls/verify_name_on_connect") is True
    assert get("transport/link/tls/close_link_on_expiration") is True
    assert get("transport/link/tls/root_ca_certificate") == str(swarm_pki.ca_cert.resolve())
    assert get("transport/link/tls/connect_certificate") == get(
        "transport/link/tls/listen_certificate"
    )
    assert get("access_control/default_permission") == "deny"
    subjects = get("access_control/subjects")
    assert isinstance(subjects, list)
    assert {s["id"] for s in subjects} == {f"cn-{n}" for n in swarm_pki.identities.members}
    no_acl = MeshConfig(
        listen=["tls/127.0.0.1:0"], security=swarm_pki.security_for("uav1", acl=False)
    )
    assert json.loads(build_zenoh_config(no_acl).get_json("access_control/enabled")) is False


def test_security_section_from_toml_names_the_key(tmp_path: Path, swarm_pki: SwarmPki) -> None:
    path = tmp_path / "uav.toml"
    path.write_text(
        'uav = "uav0"\n[mesh]\nlisten = ["tls/0.0.0.0:7447"]\n'
        f'[mesh.security]\nidentity = "uav0"\nca = "{swarm_pki.ca_cert}"\n'
        'cert = "c"\nkey = "k"\nidentities = "i"\nsigning_keys = "typo"\n'
    )
    with pytest.raises(ConfigError, match=r"mesh\.security\.signing_keys"):
        load_config(path, UavConfig)
    path.write_text('uav = "uav0"\n[mesh]\nlisten = ["tcp/0.0.0.0:7447"]\n')
    with pytest.raises(ConfigError, match="plain link off this machine"):
        load_config(path, UavConfig)
