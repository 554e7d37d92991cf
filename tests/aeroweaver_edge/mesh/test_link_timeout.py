"""Every TCP link of a mesh gets TCP_USER_TIMEOUT = the lease (real zenoh sessions on
loopback), so a link that dies silently is aborted by the kernel instead of blocking a zenoh
RX thread in close(2) for SO_LINGER's 10 s (docs/reliability.md, "Partition and heal")."""

from __future__ import annotations

import asyncio
import os
import socket
import sys

import pytest

from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.mesh.link_timeout import parse_locator, set_user_timeout
from aeroweaver_edge.mesh.session import Mesh
from tests.helpers.zenoh_net import free_port

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="TCP_USER_TIMEOUT")


@pytest.mark.parametrize(
    ("locator", "parsed"),
    [
        ("tcp/127.0.0.1:7447", ("127.0.0.1", 7447)),
        ("tls/10.0.0.1:7447#iface=wlan0", ("10.0.0.1", 7447)),
        ("tcp/[::1]:7000", ("::1", 7000)),
        ("udp/127.0.0.1:7447", None),
        ("quic/127.0.0.1:7447", None),
        ("unixsock-stream//tmp/x.sock", None),
        ("tcp/127.0.0.1", None),
        ("garbage", None),
    ],
)
def test_only_tcp_and_tls_locators_name_a_socket(
    locator: str, parsed: tuple[str, int] | None
) -> None:
    assert parse_locator(locator) == parsed


def user_timeouts(port: int) -> list[int]:
    """TCP_USER_TIMEOUT of this process's connected sockets with ``port`` at either end."""
    out = []
    for name in os.listdir("/proc/self/fd"):
        try:
            if not os.readlink(f"/proc/self/fd/{name}").startswith("socket:"):
                continue
            sock = socket.socket(fileno=os.dup(int(name)))
        except OSError:
            continue
        with sock:
            if sock.family not in (socket.AF_INET, socket.AF_INET6):
                continue
            try:
                ends = (sock.getsockname()[1], sock.getpeername()[1])
            except OSError:
                continue
            if port in ends:
                out.append(sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_USER_TIMEOUT))
    return out


@linux_only
async def test_both_ends_of_a_mesh_link_get_the_lease_as_user_timeout() -> None:
    port = free_port()
    router = await Mesh.open(
        MeshConfig(mode="router", listen=[f"tcp/127.0.0.1:{port}"], namespace="lt",
                   lease_ms=2000, insecure=True),
        node_id="router",
    )  # fmt: skip
    try:
        client = await Mesh.open(
            MeshConfig(mode="client", listen=[], connect=[f"tcp/127.0.0.1:{port}"],
                       namespace="lt", lease_ms=2000, insecure=True),
            node_id="client",
        )  # fmt: skip
        try:
            for _ in range(100):  # bounded: 10 s
                if user_timeouts(port) == [2000, 2000]:
                    break
                await asyncio.sleep(0.1)
            assert user_timeouts(port) == [2000, 2000]  # the router's end and the client's
        finally:
            await client.aclose()
    finally:
        await router.aclose()


@linux_only
def test_only_the_socket_with_both_addresses_is_touched() -> None:
    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        with (
            socket.create_connection(("127.0.0.1", port)) as a,
            socket.create_connection(("127.0.0.1", port)) as b,
        ):
            n = set_user_timeout(a.getsockname(), ("127.0.0.1", port), 1234)
            assert n == 1
            assert a.getsockopt(socket.IPPROTO_TCP, socket.TCP_USER_TIMEOUT) == 1234
            assert b.getsockopt(socket.IPPROTO_TCP, socket.TCP_USER_TIMEOUT) == 0
            a.sendall(b"still open")  # the duplicate was closed, not the socket
        assert set_user_timeout(("127.0.0.1", 1), ("127.0.0.1", 2), 1234) == 0
