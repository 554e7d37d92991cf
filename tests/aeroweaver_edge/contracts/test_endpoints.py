"""The one endpoint check every command uses (``keys init``, ``mission start``, ``console``)."""

from __future__ import annotations

import argparse

import pytest

from aeroweaver_edge.contracts.endpoints import (
    check_endpoint,
    endpoint_arg,
    endpoint_problem,
    is_host,
)
from aeroweaver_edge.contracts.errors import UserError


@pytest.mark.parametrize(
    "endpoint",
    [
        "tls/127.0.0.1:7447",
        "tcp/[::1]:7447",
        "quic/router.lan:7447",
        "tls/10.0.0.1:7447#iface=wlan0",
        "udp/192.168.1.5:65535",
        "unixsock-stream//tmp/zenoh.sock",
    ],
)
def test_good_endpoints(endpoint: str) -> None:
    assert endpoint_problem(endpoint, "connect") is None
    assert check_endpoint(endpoint, "--connect") == endpoint


@pytest.mark.parametrize(
    ("endpoint", "use", "problem"),
    [
        ("tcp/127.0.0.1:99999", "connect", "port 99999 is outside 1..65535"),
        ("tcp/127.0.0.1:0", "connect", "port 0 is outside 1..65535"),
        ("tcp/127.0.0.1:65536", "listen", "port 65536 is outside 0..65535"),
        ("tcp/127.0.0.1:-1", "listen", "port '-1' is not a number"),
        ("tcp/127.0.0.1", "connect", "expected host:port"),
        ("tcp/:7447", "connect", "expected host:port"),
        ("http/127.0.0.1:80", "connect", "unknown protocol 'http'"),
        ("127.0.0.1:7447", "connect", "not a Zenoh endpoint"),
        ("tls/not an addr!:7447", "connect", "not an IP address or a DNS name"),
        ("tls/[::1:7447", "connect", "IPv6"),
        ("tls/[nope]:7447", "connect", "not an IPv6 address"),
        ("unixsock-stream/", "connect", "not a Zenoh endpoint"),
    ],
)
def test_bad_endpoints_name_the_problem(endpoint: str, use: str, problem: str) -> None:
    found = endpoint_problem(endpoint, use)  # type: ignore[arg-type]
    assert found is not None
    assert problem in found
    with pytest.raises(UserError, match="--connect"):
        check_endpoint(endpoint, "--connect", use)  # type: ignore[arg-type]
    with pytest.raises(argparse.ArgumentTypeError):
        endpoint_arg(use)(endpoint)  # type: ignore[arg-type]


def test_listen_may_take_port_zero() -> None:
    assert endpoint_problem("tls/127.0.0.1:0", "listen") is None


@pytest.mark.parametrize(
    ("text", "ok"),
    [
        ("10.0.0.1", True),
        ("::1", True),
        ("uav1.lan", True),
        ("router", True),
        ("a" * 63 + ".example", True),
        ("a" * 64 + ".example", False),
        ("not an addr!", False),
        ("-bad.example", False),
        ("under_score", False),
        ("", False),
    ],
)
def test_hosts(text: str, ok: bool) -> None:
    assert is_host(text) is ok
