"""UDP endpoints for MAVLink, as asyncio datagram protocols (nothing blocks the loop).

``udpin://HOST:PORT`` binds and answers whoever the vehicle's datagrams come from (PX4
SITL and a companion link work this way: the autopilot sends to 14540+i); ``udpout://HOST:PORT``
sends to a fixed address from an ephemeral port.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable

from aeroweaver_edge.contracts.endpoints import UdpUrl

Addr = tuple[str, int]


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, on_datagram: Callable[[bytes, Addr], None]) -> None:
        self._on_datagram = on_datagram
        self.errors = 0

    def datagram_received(self, data: bytes, addr: Addr) -> None:
        self._on_datagram(data, (addr[0], addr[1]))

    def error_received(self, exc: Exception) -> None:
        self.errors += 1  # e.g. ICMP port unreachable while the peer is not up yet


class UdpEndpoint:
    """One UDP socket: receive every datagram, send to a fixed or learned remote."""

    def __init__(self, transport: asyncio.DatagramTransport, protocol: _Protocol) -> None:
        self._transport = transport
        self._protocol = protocol
        self.remote: Addr | None = None

    @classmethod
    async def open(cls, url: UdpUrl, on_datagram: Callable[[bytes, Addr], None]) -> UdpEndpoint:
        loop = asyncio.get_running_loop()
        local: Addr = (url.host, url.port) if url.mode == "udpin" else ("0.0.0.0", 0)
        transport, protocol = await loop.create_datagram_endpoint(
            lambda: _Protocol(on_datagram), local_addr=local
        )
        ep = cls(transport, protocol)
        if url.mode == "udpout":
            ep.remote = (url.host, url.port)
        return ep

    @property
    def local_port(self) -> int:
        return int(self._transport.get_extra_info("sockname")[1])

    @property
    def errors(self) -> int:
        return self._protocol.errors

    def send(self, data: bytes, addr: Addr | None = None) -> bool:
        """Send to ``addr`` or the remote; False when there is nowhere to send yet."""
        to = addr or self.remote
        if to is None or self._transport.is_closing():
            return False
        self._transport.sendto(data, to)
        return True

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._transport.close()
