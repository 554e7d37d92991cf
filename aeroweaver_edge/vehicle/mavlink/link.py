"""One companion-to-autopilot MAVLink link on the event loop.

It discovers the vehicle from its HEARTBEAT (the system id comes from the heartbeat, or
must match the configured one), then speaks as that system id with the onboard-computer
component id and only ever addresses that system (own-body scoping). Everything from any
other system id is dropped and counted. A heartbeat task says we are here at 1 Hz; a
watchdog marks the link lost when the vehicle's heartbeat stops.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from aeroweaver_edge.contracts.endpoints import UdpUrl
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_edge.vehicle.mavlink.codec import (
    AUTOPILOT_COMPID,
    COMPANION_COMPID,
    Codec,
    Message,
    mavlink,
)
from aeroweaver_edge.vehicle.mavlink.udp import Addr, UdpEndpoint

log = logging.getLogger(__name__)

Predicate = Callable[[Message], bool]
_NON_VEHICLE_TYPES = {
    mavlink.MAV_TYPE_GCS,
    mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
    mavlink.MAV_TYPE_GIMBAL,
    mavlink.MAV_TYPE_ADSB,
    mavlink.MAV_TYPE_CAMERA,
}


class LinkError(RuntimeError):
    """The vehicle could not be reached or refused us; the message says why."""


@dataclass
class LinkStats:
    foreign: Counter[int] = field(default_factory=Counter)  # dropped, by source sysid
    sent_to: Counter[int] = field(default_factory=Counter)  # target_system of what we sent
    datagrams: int = 0
    losses: int = 0  # times the link was declared lost


class FlightLink:
    """Codec + UDP + dispatch + heartbeat + link watchdog for one vehicle."""

    def __init__(
        self,
        url: UdpUrl,
        *,
        sysid: int | None = None,
        compid: int = COMPANION_COMPID,
        link_timeout_s: float = 2.0,
        heartbeat_hz: float = 1.0,
    ) -> None:
        if sysid is not None and not 1 <= sysid <= 255:
            raise ValueError(f"sysid must be 1..255, got {sysid}")
        self.url = url
        self.codec = Codec(sysid or 0, compid)
        self.compid = compid
        self.sysid: int | None = sysid  # the vehicle's (and therefore our) system id
        self.link_timeout_s = link_timeout_s
        self.heartbeat_period_s = 1.0 / heartbeat_hz
        self.stats = LinkStats()
        self.last: dict[str, Message] = {}
        self.last_at: dict[str, float] = {}
        self.heartbeat: Message | None = None
        self.heartbeat_at = -1.0
        self.lost = False  # after a loss until the vehicle's heartbeat is back
        self._ep: UdpEndpoint | None = None
        self._waiters: dict[str, list[tuple[Predicate, asyncio.Future[Message]]]] = {}
        self._handlers: dict[str, list[Callable[[Message], None]]] = {}
        self._on_link: list[Callable[[bool], None]] = []
        self._tasks: list[asyncio.Task[Any]] = []
        self._discovered = asyncio.Event()

    # -- lifecycle ------------------------------------------------------------------------

    async def open(self) -> None:
        """Bind the socket (idempotent); ``local_port`` is known from here on."""
        if self._ep is None:
            self._ep = await UdpEndpoint.open(self.url, self._on_datagram)

    async def connect(self, timeout_s: float) -> Message:
        """Wait for the vehicle's heartbeat, then start our heartbeat and the watchdog."""
        if self._ep is None:
            await self.open()
        try:
            async with asyncio.timeout(timeout_s):
                await self._discovered.wait()
        except TimeoutError:
            who = f"system {self.sysid}" if self.sysid else "an autopilot"
            raise LinkError(
                f"no heartbeat from {who} on {self.url} within {timeout_s:g} s"
            ) from None
        self._tasks = [
            asyncio.create_task(self._heartbeat_loop(), name=f"mav{self.sysid}-heartbeat"),
            asyncio.create_task(self._watchdog(), name=f"mav{self.sysid}-watchdog"),
        ]
        assert self.heartbeat is not None
        return self.heartbeat

    async def aclose(self) -> None:
        await cancel_all(self._tasks)
        if self._ep is not None:
            self._ep.close()
            self._ep = None
        for waiters in self._waiters.values():
            for _pred, fut in waiters:
                if not fut.done():
                    fut.cancel()
        self._waiters.clear()

    @property
    def alive(self) -> bool:
        return self.heartbeat is not None and not self.lost

    @property
    def local_port(self) -> int:
        return self._ep.local_port if self._ep is not None else 0

    # -- receiving ------------------------------------------------------------------------

    def _on_datagram(self, data: bytes, addr: Addr) -> None:
        self.stats.datagrams += 1
        for msg in self.codec.decode(data):
            self._dispatch(msg, addr)

    def _is_vehicle_heartbeat(self, msg: Message) -> bool:
        return (
            msg.get_type() == "HEARTBEAT"
            and msg.type not in _NON_VEHICLE_TYPES
            and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID
        )

    def _dispatch(self, msg: Message, addr: Addr) -> None:
        src, comp = msg.get_srcSystem(), msg.get_srcComponent()
        if self.sysid is None:
            if not self._is_vehicle_heartbeat(msg):
                self.stats.foreign[src] += 1
                return
            self.sysid = src
            self.codec.src_system = src
            log.info("vehicle discovered: system id %d from its heartbeat", src)
        if src != self.sysid or comp == self.compid:
            self.stats.foreign[src] += 1  # another vehicle's traffic, or our own echo
            return
        kind = msg.get_type()
        now = time.monotonic()
        if kind == "HEARTBEAT" and comp == AUTOPILOT_COMPID and self._is_vehicle_heartbeat(msg):
            if self._ep is not None and self.url.mode == "udpin":
                self._ep.remote = addr  # answer where the vehicle speaks from
            self.heartbeat, self.heartbeat_at = msg, now
            self._discovered.set()
            if self.lost:
                self.lost = False
                log.warning("system %d: link back", self.sysid)
                self._notify_link(True)
        self.last[kind] = msg
        self.last_at[kind] = now
        for cb in list(self._handlers.get(kind, ())):
            cb(msg)
        waiters = self._waiters.get(kind)
        if waiters:
            keep = []
            for pred, fut in waiters:
                if fut.done():
                    continue
                if pred(msg):
                    fut.set_result(msg)
                else:
                    keep.append((pred, fut))
            self._waiters[kind] = keep

    def on(self, kind: str, callback: Callable[[Message], None]) -> None:
        self._handlers.setdefault(kind, []).append(callback)

    def on_link_change(self, callback: Callable[[bool], None]) -> None:
        """``callback(False)`` when the link is declared lost, ``callback(True)`` when back."""
        self._on_link.append(callback)

    def expect(self, kind: str, pred: Predicate = lambda _m: True) -> asyncio.Future[Message]:
        """A future for the next ``kind`` message matching ``pred`` (register before sending)."""
        fut: asyncio.Future[Message] = asyncio.get_running_loop().create_future()
        self._waiters.setdefault(kind, []).append((pred, fut))
        return fut

    async def wait_for(
        self, kind: str, pred: Predicate = lambda _m: True, timeout_s: float = 1.0
    ) -> Message | None:
        return await self.wait_future(self.expect(kind, pred), timeout_s)

    def age(self, kind: str) -> float:
        """Seconds since the last ``kind`` message (inf if never)."""
        at = self.last_at.get(kind)
        return float("inf") if at is None else time.monotonic() - at

    # -- sending --------------------------------------------------------------------------

    @property
    def target(self) -> tuple[int, int]:
        """(system, component) every command goes to: our own vehicle's autopilot only."""
        if self.sysid is None:
            raise LinkError("no vehicle discovered yet")
        return self.sysid, AUTOPILOT_COMPID

    def send(self, msg: Message) -> bool:
        """Frame and send ``msg``. Refuses a message addressed to any other system."""
        target = getattr(msg, "target_system", None)
        if target is not None:
            if target != self.sysid:
                raise LinkError(
                    f"refusing to address system {target}: this link flies {self.sysid}"
                )
            self.stats.sent_to[int(target)] += 1
        if self._ep is None:
            return False
        return self._ep.send(self.codec.encode(msg))

    @property
    def mav(self) -> Any:
        """The pymavlink encoder (``*_encode`` builders)."""
        return self.codec.mav

    def beat(self) -> None:
        """One heartbeat now, outside the 1 Hz loop: before arming, so an autopilot that
        only arms its GCS failsafe once it heard its GCS (ArduCopter) has heard us."""
        self._send_heartbeat()

    def _send_heartbeat(self) -> None:
        self.send(
            self.mav.heartbeat_encode(
                mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                mavlink.MAV_AUTOPILOT_INVALID,
                0,
                0,
                mavlink.MAV_STATE_ACTIVE,
            )
        )

    async def _heartbeat_loop(self) -> None:
        while True:
            self._send_heartbeat()
            await asyncio.sleep(self.heartbeat_period_s)

    def _notify_link(self, up: bool) -> None:
        for cb in list(self._on_link):
            try:
                cb(up)
            except Exception:  # a listener bug must not stop the watchdog
                log.exception("link listener failed")

    async def _watchdog(self) -> None:
        """Declare the link lost after ``link_timeout_s`` without a vehicle heartbeat."""
        period = min(0.1, self.link_timeout_s / 5)
        while True:
            await asyncio.sleep(period)
            silent = time.monotonic() - self.heartbeat_at
            if not self.lost and silent > self.link_timeout_s:
                self.lost = True
                self.stats.losses += 1
                log.warning("system %s: no heartbeat for %.1f s: link lost", self.sysid, silent)
                self._notify_link(False)

    async def wait_future(self, fut: asyncio.Future[Message], timeout_s: float) -> Message | None:
        """Await a future from :meth:`expect`; None (and the future cancelled) on timeout."""
        try:
            async with asyncio.timeout(timeout_s):  # never wait_for: see lifecycle's docstring
                return await fut
        except TimeoutError:
            return None
