"""Addresses as a user types them, checked once, here.

Zenoh endpoints (``proto/address[?metadata][#config]``): ``keys init``, ``mission start``,
``console``, ``approve`` and ``mcp`` refuse the same mistakes with the same line (an unknown
protocol, a port outside 1..65535, no host).

Zenoh itself accepts ``tcp/127.0.0.1:99999`` and only fails when it dials; a typo should
stop the command before anything starts.

MAVLink UDP URLs (``udpin://HOST:PORT``, ``udpout://HOST:PORT``: ``UdpUrl``), which
``[vehicle] url`` is checked against when a config loads.
"""

from __future__ import annotations

import argparse
import ipaddress
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal
from urllib.parse import urlsplit

from aeroweaver_edge.contracts.errors import UserError

HOST_PORT_PROTOCOLS = frozenset({"tcp", "udp", "tls", "quic", "ws"})
"""Protocols whose address is ``host:port`` (IPv4, ``[IPv6]`` or a DNS name)."""
PATH_PROTOCOLS = frozenset({"unixsock-stream", "unixpipe", "serial", "vsock"})
"""Local protocols whose address is a path or device (not checked beyond being present)."""
PROTOCOLS = HOST_PORT_PROTOCOLS | PATH_PROTOCOLS

_DNS_LABEL = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")

Use = Literal["listen", "connect"]


def is_host(text: str) -> bool:
    """An IP address (v4 or v6) or a DNS name (RFC 1123 labels, at most 253 characters)."""
    try:
        ipaddress.ip_address(text)
        return True
    except ValueError:
        pass
    name = text.removesuffix(".")
    if not name or len(name) > 253:
        return False
    return all(_DNS_LABEL.match(label) for label in name.split("."))


def endpoint_problem(endpoint: str, use: Use = "connect") -> str | None:
    """Why ``endpoint`` is not a usable Zenoh endpoint, or None. Port 0 (the OS picks one)
    is fine to listen on, never to dial."""
    proto, sep, rest = endpoint.partition("/")
    if not sep or not proto or not rest:
        return "not a Zenoh endpoint (expected proto/host:port, e.g. tls/10.0.0.1:7447)"
    if proto not in PROTOCOLS:
        return f"unknown protocol {proto!r} (known: {', '.join(sorted(PROTOCOLS))})"
    address = rest.split("#", 1)[0].split("?", 1)[0]
    if proto in PATH_PROTOCOLS:
        return None if address else "no address after the protocol"
    host, colon, port_text = address.rpartition(":")
    if not colon or not host:
        return "expected host:port after the protocol"
    if host.startswith("["):
        if not host.endswith("]"):
            return f"host {host!r}: an IPv6 address is written [addr]"
        try:
            ipaddress.IPv6Address(host[1:-1].split("%", 1)[0])
        except ValueError:
            return f"host {host!r} is not an IPv6 address"
    elif not is_host(host):
        return f"host {host!r} is not an IP address or a DNS name"
    if not port_text.isdigit():
        return f"port {port_text!r} is not a number"
    port, low = int(port_text), 0 if use == "listen" else 1
    if not low <= port <= 65535:
        return f"port {port} is outside {low}..65535"
    return None


def check_endpoint(endpoint: str, flag: str, use: Use = "connect") -> str:
    """``endpoint`` unchanged, or a one-line ``UserError`` naming ``flag``."""
    problem = endpoint_problem(endpoint, use)
    if problem is not None:
        raise UserError(f"{flag} {endpoint!r}: {problem}")
    return endpoint


def endpoint_arg(use: Use) -> Callable[[str], str]:
    """An argparse type for ``--listen`` / ``--connect``: a bad endpoint is a usage error."""

    def parse(text: str) -> str:
        problem = endpoint_problem(text, use)
        if problem is not None:
            raise argparse.ArgumentTypeError(f"{text!r}: {problem}")
        return text

    parse.__name__ = f"{use} endpoint"
    return parse


@dataclass(frozen=True)
class UdpUrl:
    mode: Literal["udpin", "udpout"]
    host: str
    port: int

    @classmethod
    def parse(cls, url: str) -> UdpUrl:
        """``udpin://0.0.0.0:14540`` or ``udpout://127.0.0.1:14580``; anything else is a
        ``ValueError`` that names the problem."""
        parts = urlsplit(url)
        if parts.scheme not in ("udpin", "udpout"):
            raise ValueError(
                f"{url!r}: scheme must be udpin:// or udpout:// (got {parts.scheme!r})"
            )
        try:
            port = parts.port
        except ValueError:
            port = None
        if not parts.hostname or port is None or not 0 <= port <= 65535:
            raise ValueError(f"{url!r}: expected HOST:PORT with a port 0-65535")
        if parts.scheme == "udpout" and port == 0:
            raise ValueError(f"{url!r}: udpout needs a real destination port")
        mode: Literal["udpin", "udpout"] = "udpin" if parts.scheme == "udpin" else "udpout"
        return cls(mode, parts.hostname, port)

    def __str__(self) -> str:
        return f"{self.mode}://{self.host}:{self.port}"


__all__ = ["UdpUrl", "check_endpoint", "endpoint_arg", "endpoint_problem", "is_host"]
