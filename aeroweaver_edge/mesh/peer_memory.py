"""An in-memory ``PeerChannel``: the talk side of a swarm without a network.

Shipped with the library, like httpx's ``MockTransport``: tests drive ``decision_round`` and
the daemon through it, and a benchmark can run many UAVs in one process without Zenoh. It
behaves like ``PeerLink`` where it matters: the roster holds the other announced channels,
``send("*")`` reaches every channel (listen-only ones too), a named send needs the peer in
the roster, and acceptance (reach rule on the positions of the sending round, ordering,
waiting for expected messages) is the same ``Inbox`` code. Delivery is immediate and in
order; headers get sequence numbers like real payloads, so replays are still refused.

    hub = MemoryPeerHub()
    a, b = hub.channel("uav0"), hub.channel("uav1")
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from aeroweaver_edge.contracts.defaults import COMM_RADIUS_M
from aeroweaver_edge.contracts.ports import Reach, Scalar
from aeroweaver_edge.contracts.wire import (
    BROADCAST,
    HeaderFactory,
    InboxMessage,
    MessagePurpose,
    MsgRef,
    ReplayFilter,
    StateBeacon,
    Vec3,
)
from aeroweaver_edge.mesh.inbox import Inbox, PeerStats


class MemoryPeerHub:
    """The shared medium of a set of in-memory channels."""

    def __init__(self, comm_radius_m: float = COMM_RADIUS_M) -> None:
        self.comm_radius_m = comm_radius_m
        self.channels: dict[str, MemoryPeerChannel] = {}
        self.beacons: dict[str, StateBeacon] = {}

    def channel(
        self, uav: str, *, announce: bool = True, headers: HeaderFactory | None = None
    ) -> MemoryPeerChannel:
        """Join ``uav`` to the hub (``announce=False``: listen-only, in nobody's roster)."""
        if uav in self.channels:
            raise ValueError(f"{uav!r} already has a channel on this hub")
        ch = MemoryPeerChannel(self, uav, headers or HeaderFactory(uav), announce=announce)
        self.channels[uav] = ch
        for other in self.channels.values():
            other.inbox.notify()
        return ch

    def _leave(self, uav: str) -> None:
        self.channels.pop(uav, None)
        self.beacons.pop(uav, None)
        for other in self.channels.values():
            other.inbox.notify()

    def _deliver(self, msg: InboxMessage) -> None:
        if msg.to == BROADCAST:
            targets = [c for u, c in self.channels.items() if u != msg.h.sender]
        else:
            target = self.channels.get(msg.to)
            targets = [] if target is None else [target]
        for ch in targets:
            ch._receive(msg)


class MemoryPeerChannel:
    """One UAV's end of a ``MemoryPeerHub``; serves the ``PeerChannel`` port."""

    def __init__(
        self, hub: MemoryPeerHub, uav: str, headers: HeaderFactory, *, announce: bool
    ) -> None:
        if headers.sender != uav:
            raise ValueError(f"header factory sends as {headers.sender!r}, not {uav!r}")
        self.uav = uav
        self.announce = announce
        self.inbox = Inbox(uav, hub.comm_radius_m)
        self._hub = hub
        self._headers = headers
        self._replay = ReplayFilter()
        self._own: StateBeacon | None = None
        self._closed = False

    @property
    def stats(self) -> PeerStats:
        return self.inbox.stats

    @property
    def roster(self) -> frozenset[str]:
        return frozenset(u for u, c in self._hub.channels.items() if c.announce and u != self.uav)

    @property
    def neighbours(self) -> Mapping[str, StateBeacon]:
        return {u: b for u, b in self._hub.beacons.items() if u != self.uav}

    def set_routing(self, role: str, reach: Reach) -> None:
        self.inbox.set_routing(role, reach)

    def publish_beacon(
        self, round: int, pos: Vec3, vel: Vec3, role: str = "", status: str = "nominal"
    ) -> None:
        beacon = StateBeacon(
            h=self._headers.next(), uav=self.uav, round=round, pos=pos, vel=vel, role=role,
            status=status,
        )  # fmt: skip
        self._own = beacon
        self.inbox.note_position(round, pos)
        if self.announce:
            self._hub.beacons[self.uav] = beacon

    async def send(
        self,
        to: str,
        kind: str,
        body: Mapping[str, Scalar],
        *,
        round: int,
        purpose: MessagePurpose = "coordination",
    ) -> MsgRef | None:
        reason: str | None = None
        if self._closed:
            reason = "closed"
        elif self._own is None:
            reason = "no_own_position"
        elif to != BROADCAST and to not in self.roster:
            reason = "unknown_peer"
        if reason is not None or self._own is None:
            self.stats.dropped[reason or "no_own_position"] += 1
            return None
        msg = InboxMessage(
            h=self._headers.next(),
            to=to,
            round=round,
            kind=kind,
            body=dict(body),
            sender_pos=self._own.pos,
            sender_role=self.inbox.role,
            purpose=purpose,
        )
        self.stats.sent += 1
        self._hub._deliver(msg)
        return MsgRef(sender=self.uav, seq=msg.h.seq, to=to)

    def _receive(self, msg: InboxMessage) -> None:
        if self._closed:
            return
        if msg.h.sender not in self.roster:
            self.inbox.reject("unknown_sender", msg.h.sender)
        elif not self._replay.accept(msg.h):
            self.inbox.reject("replay", msg.h.sender)
        else:
            self.inbox.offer(msg)

    def inject(self, msg: InboxMessage) -> None:
        """Deliver a hand-made message as if it came over the medium (tests: replays,
        foreign senders)."""
        self._receive(msg)

    async def collect_inbox(
        self,
        expect: Iterable[MsgRef] = (),
        timeout_s: float = 1.0,
        *,
        max_round: int | None = None,
    ) -> list[InboxMessage]:
        return await self.inbox.collect(expect, timeout_s, max_round=max_round)

    async def aclose(self) -> None:
        self._closed = True
        self._hub._leave(self.uav)


__all__ = ["MemoryPeerChannel", "MemoryPeerHub"]
