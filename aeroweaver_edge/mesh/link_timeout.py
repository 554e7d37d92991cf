"""Give every TCP/TLS link of a zenoh session a kernel user timeout (``TCP_USER_TIMEOUT``)
equal to the mesh lease, so a silently dead link cannot block a zenoh thread for 10 s.

Why: zenoh 1.10 sets ``SO_LINGER`` = 10 s on its TCP and TLS sockets (a compile-time
constant) and closes a link whose lease expired from a task on its RX runtime. A link cut
without FIN or RST (a radio partition) always has unacknowledged bytes queued, so that
``close(2)`` waits in the kernel (``sk_stream_wait_close``) for the whole linger, and the RX
thread serves no other link meanwhile: with two links dying together a router with zenoh's
two RX threads heard nobody for 10 s (docs/reliability.md, "Partition and heal"). With a
user timeout the kernel itself aborts a connection whose sent data stayed unacknowledged
that long; an aborted socket closes at once. Zenoh has no configuration key for either
option, so this sets it on the sockets themselves: a link event (the zenoh callback only
enqueues it) names the link's two addresses, and a worker thread finds the process's socket
with exactly those addresses and sets the option on it. Linux only; elsewhere nothing.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import sys
from typing import Any

import zenoh

log = logging.getLogger(__name__)

TCP_USER_TIMEOUT = getattr(socket, "TCP_USER_TIMEOUT", 18)  # linux/tcp.h
STREAM_PROTOCOLS = ("tcp", "tls")


def parse_locator(locator: str) -> tuple[str, int] | None:
    """``tcp/127.0.0.1:7447`` or ``tls/[::1]:7447#iface=x`` -> (host, port); None for
    anything not carried over a TCP socket (udp, unix sockets, quic...)."""
    proto, sep, rest = str(locator).partition("/")
    if not sep or proto not in STREAM_PROTOCOLS:
        return None
    address = rest.split("?", 1)[0].split("#", 1)[0]
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit():
        return None
    return host.strip("[]"), int(port)


def _same(addr: Any, want: tuple[str, int]) -> bool:
    """A socket address (v4 or v6 tuple) equal to ``want``, v4-mapped v6 included."""
    if not isinstance(addr, tuple) or len(addr) < 2:
        return False
    host = str(addr[0]).removeprefix("::ffff:")
    return addr[1] == want[1] and host == want[0].removeprefix("::ffff:")


def set_user_timeout(src: tuple[str, int], dst: tuple[str, int], timeout_ms: int) -> int:
    """Set ``TCP_USER_TIMEOUT`` on this process's TCP sockets bound to ``src`` and connected
    to ``dst``; returns how many were set. A duplicate of the descriptor is used and closed
    (closing a duplicate never closes the socket itself)."""
    done = 0
    try:
        fds = os.listdir("/proc/self/fd")
    except OSError:
        return 0
    for name in fds:
        try:
            if not os.readlink(f"/proc/self/fd/{name}").startswith("socket:"):
                continue
            dup = os.dup(int(name))
        except (OSError, ValueError):
            continue  # closed meanwhile
        try:
            sock = socket.socket(fileno=dup)
        except OSError:
            os.close(dup)  # refused: the duplicate is still ours to close
            continue
        with sock:  # closes the duplicate only
            if sock.type != socket.SOCK_STREAM or sock.family not in (
                socket.AF_INET,
                socket.AF_INET6,
            ):
                continue
            try:
                if _same(sock.getsockname(), src) and _same(sock.getpeername(), dst):
                    sock.setsockopt(socket.IPPROTO_TCP, TCP_USER_TIMEOUT, timeout_ms)
                    done += 1
            except OSError:
                continue  # not connected (a listener) or gone
    return done


class LinkTimeouts:
    """Watches a session's links and gives each TCP/TLS one ``TCP_USER_TIMEOUT``."""

    def __init__(self, session: zenoh.Session, timeout_ms: int, node_id: str) -> None:
        self.timeout_ms = timeout_ms
        self.node_id = node_id
        self.applied = 0  # sockets given the timeout
        self.unmatched = 0  # stream links whose socket was not found
        self._loop = asyncio.get_running_loop()
        self._events: asyncio.Queue[tuple[str, str]] = asyncio.Queue()
        self._task: asyncio.Task[None] | None = None
        self._listener: Any = None
        if sys.platform.startswith("linux"):
            self._task = asyncio.create_task(self._pump(), name=f"{node_id}-link-timeouts")
            # Direct (on zenoh's own thread): an indirect callback's Python thread would
            # hang interpreter exit if the session were never closed (docs/notes/zenoh.md).
            handler = zenoh.handlers.Callback(self._on_event, indirect=False)
            self._listener = session.info.declare_link_events_listener(handler, history=True)

    def _on_event(self, event: zenoh.LinkEvent) -> None:
        """Zenoh thread: only enqueue (addresses of added links)."""
        if event.kind != zenoh.SampleKind.PUT:
            return
        item = (str(event.link.src), str(event.link.dst))
        with contextlib.suppress(RuntimeError):  # the loop is gone: nothing to do
            self._loop.call_soon_threadsafe(self._events.put_nowait, item)

    async def _pump(self) -> None:
        while True:
            src_text, dst_text = await self._events.get()
            src, dst = parse_locator(src_text), parse_locator(dst_text)
            if src is None or dst is None:
                continue
            n = await asyncio.to_thread(set_user_timeout, src, dst, self.timeout_ms)
            self.applied += n
            if n == 0:
                self.unmatched += 1
                log.debug("%s: no socket for link %s -> %s", self.node_id, src_text, dst_text)

    async def aclose(self) -> None:
        """Stop listening (in a worker thread: undeclare may wait for a callback) and stop
        the pump."""
        listener, self._listener = self._listener, None
        if listener is not None:
            with contextlib.suppress(zenoh.ZError):
                await asyncio.to_thread(listener.undeclare)
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task


__all__ = ["LinkTimeouts", "parse_locator", "set_user_timeout"]
