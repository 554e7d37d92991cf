"""One UAV's view of its peers: who is alive, where they are, and directed messages.

The roster comes from liveliness tokens, positions from state beacons, and messages from
this UAV's inbox. The communication radius (DESIGN §4.2) is enforced at the *sender* from
the latest beacons, so a simulated swarm behaves like a radio mesh. Every receive-side
check drops and counts instead of raising: a bad message must never stop the round loop.

Receive-side bounds (``PeerLimits``) are defence in depth behind the transport's TLS, ACL
and signatures: a forged future epoch cannot lock a sender out (``ReplayFilter``), pending
messages are capped per sender, in count and in bytes, and far-future rounds are dropped,
only known identities join the roster, and a beacon must be physically plausible.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections import Counter
from collections.abc import Callable, Collection, Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import msgspec

from .mesh import Declared, Mesh, MeshClosed, MeshError
from .wire import (
    HeaderFactory,
    InboxMessage,
    Keys,
    MsgRef,
    ReplayFilter,
    StateBeacon,
    Vec3,
)

log = logging.getLogger(__name__)

Body = Mapping[str, str | int | float | bool]

_ARRIVED_MEMORY = 4096  # (sender, seq) pairs remembered so an early arrival is not "missing"


@dataclass(frozen=True)
class PeerLimits:
    """Receive-side bounds of one PeerLink. ``None`` turns a check off."""

    known_peers: Collection[str] | None = None  # ids allowed in the roster (identity list)
    max_pending: int = 256  # inbox messages waiting for their round
    max_pending_per_sender: int = 64  # so one flooding peer cannot crowd out the others
    max_pending_bytes: int = 256 * 1024
    # A message (or beacon) further ahead of our round is dropped. This presumes rounds are
    # aligned across the swarm (lockstep simulation; a field clock must number rounds from a
    # shared start); None turns it off.
    future_rounds: int | None = 2
    replay_quiet_s: float = 5.0  # an unauthenticated new epoch waits this long (or a leave)
    max_epoch_step: int | None = None  # boot counters: refuse unauthenticated epoch leaps
    max_speed_mps: float | None = None  # beacon plausibility: displacement <= speed * time
    round_s: float = 0.5  # time one round stands for (lockstep rounds run faster than this)
    motion_margin_m: float = 5.0  # position noise allowed on top of speed * time
    max_abs_m: float | None = None  # no position further than this from the origin


@dataclass
class PeerStats:
    """Counters for reports and tests. ``dropped``: not sent; ``rejected``: not accepted."""

    sent: int = 0
    dropped: Counter[str] = field(default_factory=Counter)
    received: int = 0
    rejected: Counter[str] = field(default_factory=Counter)
    missing: int = 0  # expected messages that had not arrived when collect_inbox gave up


class PeerLink:
    """Roster, neighbour table and inbox of one UAV over a Mesh (which the caller owns)."""

    def __init__(
        self,
        mesh: Mesh,
        keys: Keys,
        uav: str,
        headers: HeaderFactory,
        comm_radius_m: float,
        limits: PeerLimits | None = None,
    ) -> None:
        if headers.sender != uav:
            raise ValueError(f"header factory sends as {headers.sender!r}, not {uav!r}")
        if comm_radius_m <= 0:
            raise ValueError(f"comm_radius_m must be > 0, got {comm_radius_m}")
        self.uav = uav
        self.comm_radius_m = comm_radius_m
        self.stats = PeerStats()
        self.limits = limits = limits or PeerLimits()
        self._mesh = mesh
        self._keys = keys
        self._headers = headers
        # One epoch per sender for its beacons and its messages (whichever came first fixes
        # it), each stream in its own sequence order.
        self._replay = ReplayFilter(
            quiet_s=limits.replay_quiet_s, max_epoch_step=limits.max_epoch_step
        )
        self._roster: set[str] = set()
        self._beacons: dict[str, StateBeacon] = {}
        self._beacon_seen: dict[str, float] = {}  # monotonic arrival of each latest beacon
        self._own: StateBeacon | None = None
        self._pending: list[InboxMessage] = []
        self._pending_bytes: dict[tuple[str, int], int] = {}  # (sender, seq) -> encoded size
        self._round: int | None = None  # our latest round (from our own beacon)
        self._arrived: dict[tuple[str, int], None] = {}  # insertion-ordered, bounded
        self._waiters: set[asyncio.Future[None]] = set()
        self._handles: list[Declared] = []
        self._token: Declared | None = None
        self._started = False
        self._closed = False

    # -- views ------------------------------------------------------------------------------

    @property
    def roster(self) -> frozenset[str]:
        """Live peers (not including this UAV), from liveliness."""
        return frozenset(self._roster)

    @property
    def neighbours(self) -> Mapping[str, StateBeacon]:
        """Latest beacon of each peer (read-only)."""
        return MappingProxyType(self._beacons)

    @property
    def own_beacon(self) -> StateBeacon | None:
        return self._own

    # -- lifecycle --------------------------------------------------------------------------

    async def start(self) -> None:
        """Declare everything, liveliness token last: a peer that sees our token can already
        reach our inbox and queryable (declarations travel in order; notes/zenoh.md)."""
        if self._started:
            raise RuntimeError(f"PeerLink {self.uav} already started")
        self._started = True
        keys, mesh = self._keys, self._mesh
        self._handles = [
            mesh.subscribe(keys.inbox(self.uav, "*"), InboxMessage, on_item=self._on_inbox),
            mesh.declare_queryable(keys.state(self.uav), lambda: self._own),
            mesh.subscribe(keys.state("*"), StateBeacon, on_item=self._on_beacon),
            mesh.watch_liveliness(keys.alive_uav("*"), on_item=self._on_alive),
        ]
        self._token = mesh.declare_token(keys.alive_uav(self.uav))
        await self.refresh_neighbours()

    async def refresh_neighbours(self, timeout_s: float = 0.5) -> int:
        """Ask every reachable peer's state queryable for its latest beacon, so a late joiner
        need not wait for the next beacon. Returns how many beacons were taken."""
        replies = await self._mesh.get(self._keys.state("*"), StateBeacon, timeout_s)
        return sum(self._on_beacon(item) for item in replies)

    async def aclose(self) -> None:
        """Withdraw the token first (peers stop sending), then everything else; idempotent."""
        self._closed = True
        token, self._token = self._token, None
        if token is not None:
            await token.aclose()
        handles, self._handles = self._handles, []
        for handle in handles:
            await handle.aclose()
        self._notify()

    async def wait_for_peers(self, peers: Iterable[str], timeout_s: float = 5.0) -> bool:
        """True once every id in ``peers`` is in the roster (start-up barrier)."""
        want = set(peers)
        return await self._wait_until(lambda: want <= self._roster, timeout_s)

    # -- sending ----------------------------------------------------------------------------

    def publish_beacon(
        self, round: int, pos: Vec3, vel: Vec3, role: str = "", status: str = "nominal"
    ) -> StateBeacon:
        """Publish our state (DROP: latest wins) and remember it for the radius rule."""
        beacon = StateBeacon(
            h=self._headers.next(),
            uav=self.uav,
            round=round,
            pos=pos,
            vel=vel,
            role=role,
            status=status,
        )
        self._own = beacon
        self._round = round
        self._mesh.put(self._keys.state(self.uav), beacon)
        return beacon

    async def send(
        self,
        to: str,
        kind: str,
        body: Body,
        *,
        round: int,
        min_round: int | None = None,
        wait_s: float = 0.5,
    ) -> MsgRef | None:
        """Send a directed message if ``to`` is live and within the communication radius.

        With ``min_round``, first wait up to ``wait_s`` for the recipient's beacon of that
        round, so lockstep rounds judge range on the same positions every run.
        Returns None (reason counted in ``stats.dropped``) when the message is not sent.
        """
        if min_round is not None and to in self._roster:
            await self._wait_until(lambda: self._beacon_ready(to, min_round), wait_s)
        reason = self._unreachable(to, min_round)
        if reason is None and self._own is not None:  # (_unreachable checked _own; for mypy)
            msg = InboxMessage(
                h=self._headers.next(),
                to=to,
                round=round,
                kind=kind,
                body=dict(body),
                sender_pos=self._own.pos,
            )
            try:
                self._mesh.put(self._keys.inbox(to, self.uav), msg, block=True)
            except MeshError as exc:
                reason = "closed" if isinstance(exc, MeshClosed) else "put_failed"
            else:
                self.stats.sent += 1
                return MsgRef(sender=self.uav, seq=msg.h.seq, to=to)
        self.stats.dropped[reason or "no_own_position"] += 1
        log.debug("%s -> %s: message dropped (%s)", self.uav, to, reason)
        return None

    def _unreachable(self, to: str, min_round: int | None) -> str | None:
        """Why ``to`` cannot be sent to now, judged on the latest beacons; None if it can."""
        beacon = self._beacons.get(to)
        if self._closed:
            return "closed"
        if to not in self._roster:
            return "unknown_peer"
        if beacon is None:
            return "no_beacon"
        if min_round is not None and beacon.round < min_round:
            return "stale_beacon"
        if self._own is None:
            return "no_own_position"
        if math.dist(self._own.pos, beacon.pos) > self.comm_radius_m:
            return "out_of_range"
        return None

    def _beacon_ready(self, uav: str, min_round: int) -> bool:
        """Stop waiting when the beacon is recent enough, or when the peer has left."""
        beacon = self._beacons.get(uav)
        return uav not in self._roster or (beacon is not None and beacon.round >= min_round)

    # -- receiving --------------------------------------------------------------------------

    async def collect_inbox(
        self,
        expect: Iterable[MsgRef] = (),
        timeout_s: float = 1.0,
        *,
        max_round: int | None = None,
    ) -> list[InboxMessage]:
        """Wait (at most ``timeout_s``) for every expected message, then return all accepted
        messages since the last call, sorted by (sender, seq). Missing ones are counted.

        ``max_round`` keeps messages of later rounds queued for a later call, so a fast
        sender's message still enters the recipient's *next* round (DESIGN §4.6).
        """
        want = {(ref.sender, ref.seq) for ref in expect}
        if not await self._wait_until(lambda: want <= self._arrived.keys(), timeout_s):
            missing = sorted(want - self._arrived.keys())
            self.stats.missing += len(missing)
            log.info("%s: %d expected message(s) missing: %s", self.uav, len(missing), missing)
        if max_round is None:
            out, keep = self._pending, []
        else:
            # Kept for a later round only if that round is near: leftovers of an earlier
            # episode (rounds restart at 0) or forged far-future rounds are dropped here.
            ahead = self.limits.future_rounds
            horizon = max_round + 1 + ahead if ahead is not None else None
            out = [m for m in self._pending if m.round <= max_round]
            keep = [
                m
                for m in self._pending
                if m.round > max_round and (horizon is None or m.round <= horizon)
            ]
            for _ in range(len(self._pending) - len(out) - len(keep)):
                self._reject("future_round", "pending")
        self._pending = keep
        kept = {(m.h.sender, m.h.seq) for m in keep}
        self._pending_bytes = {k: v for k, v in self._pending_bytes.items() if k in kept}
        out.sort(key=lambda m: (m.h.sender, m.h.seq))
        return out

    def _reject(self, reason: str, key: str) -> None:
        self.stats.rejected[reason] += 1
        log.debug("%s: rejected %s (%s)", self.uav, key, reason)

    def _on_inbox(self, item: tuple[str, InboxMessage]) -> None:
        key, msg = item
        sender = msg.h.sender
        if key != self._keys.inbox(self.uav, sender):
            self._reject("spoofed_sender", key)
        elif msg.to != self.uav:
            self._reject("wrong_recipient", key)
        elif sender not in self._roster:
            self._reject("unknown_sender", key)
        elif self._too_far_ahead(msg.round):
            self._reject("future_round", key)
        elif (full := self._pending_full(msg)) is not None:
            self._reject(full, key)
        elif why := self._replay.check(
            msg.h, authenticated=self._mesh.authenticated, stream="inbox"
        ):
            self._reject(why, key)
        else:
            self.stats.received += 1
            self._pending.append(msg)
            self._pending_bytes[(sender, msg.h.seq)] = len(msgspec.msgpack.encode(msg))
            self._arrived[(sender, msg.h.seq)] = None
            if len(self._arrived) > _ARRIVED_MEMORY:
                del self._arrived[next(iter(self._arrived))]
            self._notify()

    def _too_far_ahead(self, round_: int) -> bool:
        ahead = self.limits.future_rounds
        return ahead is not None and self._round is not None and round_ > self._round + ahead

    def _pending_full(self, msg: InboxMessage) -> str | None:
        """Why ``msg`` does not fit in the pending buffer (None: it fits)."""
        lim = self.limits
        if len(self._pending) >= lim.max_pending:
            return "inbox_full"
        mine = sum(1 for m in self._pending if m.h.sender == msg.h.sender)
        if mine >= lim.max_pending_per_sender:
            return "inbox_full_sender"
        size = len(msgspec.msgpack.encode(msg))
        if sum(self._pending_bytes.values()) + size > lim.max_pending_bytes:
            return "inbox_full_bytes"
        return None

    def _on_beacon(self, item: tuple[str, StateBeacon]) -> bool:
        """Latest wins by (epoch, seq); the key, the payload and the header must agree, and
        the claimed position must be physically plausible."""
        key, beacon = item
        if beacon.uav == self.uav:
            return False  # our own beacon, delivered locally
        if key != self._keys.state(beacon.uav) or beacon.h.sender != beacon.uav:
            self._reject("spoofed_beacon", key)
            return False
        known = self.limits.known_peers
        if known is not None and beacon.uav not in known:
            self._reject("unknown_peer", key)
            return False
        implausible = self._implausible(beacon)
        if implausible is not None:
            self._reject(implausible, key)
            return False
        why = self._replay.check(beacon.h, authenticated=self._mesh.authenticated, stream="beacon")
        if why is not None:
            self._reject("stale_beacon" if why == "replay" else why, key)
            return False
        self._beacons[beacon.uav] = beacon
        self._beacon_seen[beacon.uav] = time.monotonic()
        self._notify()
        return True

    def _implausible(self, beacon: StateBeacon) -> str | None:
        """Why a beacon cannot be true, or None. Rounds restart with each episode, so a
        beacon whose round is not after the previous one starts a new track (only the
        absolute bound applies); otherwise displacement <= max speed x elapsed time, where
        elapsed is the larger of the wall time since the last beacon and the rounds
        between them (a lockstep round stands for ``round_s`` however fast it runs)."""
        lim = self.limits
        if not all(math.isfinite(x) for x in (*beacon.pos, *beacon.vel)):
            return "non_finite_beacon"
        if lim.max_abs_m is not None and math.hypot(*beacon.pos) > lim.max_abs_m:
            return "implausible_position"
        if self._too_far_ahead(beacon.round):
            return "future_round"
        prev = self._beacons.get(beacon.uav)
        if lim.max_speed_mps is None or prev is None or beacon.round <= prev.round:
            return None
        elapsed = max(
            time.monotonic() - self._beacon_seen.get(beacon.uav, time.monotonic()),
            (beacon.round - prev.round) * lim.round_s,
        )
        if math.dist(prev.pos, beacon.pos) > lim.max_speed_mps * elapsed + lim.motion_margin_m:
            return "implausible_motion"
        return None

    def _on_alive(self, item: tuple[str, bool]) -> None:
        key, alive = item
        uav = key.rsplit("/", 1)[-1]
        if key != self._keys.alive_uav(uav) or uav == self.uav:
            return
        known = self.limits.known_peers
        if alive and known is not None and uav not in known:
            self._reject("unknown_peer_token", key)
            return
        if alive:
            self._roster.add(uav)
        else:
            self._roster.discard(uav)
            self._beacons.pop(uav, None)
            self._beacon_seen.pop(uav, None)
            # Its session ended: a restart's new epoch need not wait for the quiet time, and
            # its sequence numbers start again (an old (sender, seq) is not an arrival).
            self._replay.release(uav)
            self._arrived = {k: None for k in self._arrived if k[0] != uav}
        self._notify()

    # -- waiting ----------------------------------------------------------------------------

    def _notify(self) -> None:
        for fut in self._waiters:
            if not fut.done():
                fut.set_result(None)
        self._waiters.clear()

    async def _wait_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Re-check ``predicate`` on every state change until it holds or time runs out."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while not predicate():
            remaining = deadline - loop.time()
            if remaining <= 0:
                return False
            fut: asyncio.Future[None] = loop.create_future()
            self._waiters.add(fut)
            try:
                await asyncio.wait({fut}, timeout=remaining)
            finally:
                self._waiters.discard(fut)
        return True
