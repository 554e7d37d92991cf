"""One UAV's view of its peers over Zenoh: who is alive, where they are, and messages.

``PeerLink`` serves the ``PeerChannel`` port (``ports.py``). The roster comes from liveliness
tokens, positions from state beacons, messages from this UAV's inbox key (directed) and
every peer's broadcast key (``to="*"``: one put reaches every subscriber). Whether a message
*reaches* this UAV is decided on receipt by the shared ``Inbox`` (routing rule + the
positions of the round it was sent), so sending never waits for a peer. Every receive-side
check drops and counts instead of raising.

Receive-side bounds (``PeerLimits``) are defence in depth behind the transport's TLS, ACL
and signatures: a forged future epoch cannot lock a sender out (``ReplayFilter``), the
pending queue is capped (``Inbox``), only known identities join the roster, and a beacon
must be physically plausible.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterable, Mapping
from types import MappingProxyType

from aeroweaver_edge.contracts.ports import Reach, Scalar
from aeroweaver_edge.contracts.wire import (
    BROADCAST,
    HeaderFactory,
    InboxMessage,
    Keys,
    MessagePurpose,
    MsgRef,
    ReplayFilter,
    StateBeacon,
    Vec3,
)
from aeroweaver_edge.mesh.inbox import Inbox, PeerLimits, PeerStats
from aeroweaver_edge.mesh.session import Declared, Mesh, MeshClosed, MeshError

log = logging.getLogger(__name__)

Body = Mapping[str, Scalar]


class PeerLink:
    """Roster, neighbour table and inbox of one UAV over a Mesh (which the caller owns).

    ``announce=False`` makes a listen-only link (no liveliness token, no state queryable):
    the simulated world uses it for the opponents it flies that hear messages (the
    eavesdropper), which must not appear in any roster.

    ``track_neighbours=True`` also subscribes to every peer's beacon to keep ``neighbours``
    current. Off by default: nothing in a round needs peers' beacons (range is judged by
    receivers from the positions messages carry), and following every beacon costs each UAV
    one delivery per peer per round, O(N^2) for the swarm. ``refresh_neighbours`` still
    fetches them on demand from the peers' state queryables.
    """

    def __init__(
        self,
        mesh: Mesh,
        keys: Keys,
        uav: str,
        headers: HeaderFactory,
        comm_radius_m: float,
        *,
        announce: bool = True,
        track_neighbours: bool = False,
        limits: PeerLimits | None = None,
    ) -> None:
        if headers.sender != uav:
            raise ValueError(f"header factory sends as {headers.sender!r}, not {uav!r}")
        self.uav = uav
        self.comm_radius_m = comm_radius_m
        self.limits = limits = limits or PeerLimits()
        self.inbox = Inbox(uav, comm_radius_m, limits)
        self.announce = announce
        self.track_neighbours = track_neighbours
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
        self._handles: list[Declared] = []
        self._token: Declared | None = None
        self._started = False
        self._closed = False

    # -- views ------------------------------------------------------------------------------

    @property
    def stats(self) -> PeerStats:
        return self.inbox.stats

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

    def set_routing(self, role: str, reach: Reach) -> None:
        self.inbox.set_routing(role, reach)

    # -- lifecycle --------------------------------------------------------------------------

    async def start(self) -> None:
        """Declare everything, liveliness token last: a peer that sees our token can already
        reach our inbox and queryable (declarations travel in order; docs/notes/zenoh.md)."""
        if self._started:
            raise RuntimeError(f"PeerLink {self.uav} already started")
        self._started = True
        keys, mesh = self._keys, self._mesh
        self._handles = [
            mesh.subscribe(keys.inbox(self.uav, "*"), InboxMessage, on_item=self._on_inbox,
                           precheck=self._precheck_inbox),
            mesh.subscribe(keys.broadcast("*"), InboxMessage, on_item=self._on_broadcast,
                           precheck=self._precheck_broadcast),
            mesh.watch_liveliness(keys.alive_uav("*"), on_item=self._on_alive),
        ]  # fmt: skip
        if self.track_neighbours:
            self._handles.append(
                mesh.subscribe(keys.state("*"), StateBeacon, on_item=self._on_beacon,
                               precheck=self._precheck_beacon)
            )  # fmt: skip
        if self.announce:
            self._handles.append(mesh.declare_queryable(keys.state(self.uav), lambda: self._own))
            self._token = mesh.declare_token(keys.alive_uav(self.uav))
            if self.track_neighbours:
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
        self.inbox.notify()

    async def wait_for_peers(self, peers: Iterable[str], timeout_s: float = 5.0) -> bool:
        """True once every id in ``peers`` is in the roster (start-up barrier)."""
        want = set(peers)
        return await self.inbox.wait_until(lambda: want <= self._roster, timeout_s)

    # -- sending ----------------------------------------------------------------------------

    def publish_beacon(
        self, round: int, pos: Vec3, vel: Vec3, role: str = "", status: str = "nominal"
    ) -> None:
        """Publish our state (DROP: latest wins); remember our position in this round."""
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
        self.inbox.note_position(round, pos)
        self._mesh.note_round()  # every peer's verification budget gains a round's share
        self._mesh.put(self._keys.state(self.uav), beacon)

    async def send(
        self,
        to: str,
        kind: str,
        body: Body,
        *,
        round: int,
        purpose: MessagePurpose = "coordination",
    ) -> MsgRef | None:
        """Send a message now; ``to="*"`` broadcasts. Never waits for a peer: whether it
        reaches anyone is judged by each receiver. None (counted) when it cannot be sent."""
        reason: str | None = None
        if self._closed:
            reason = "closed"
        elif self._own is None:
            reason = "no_own_position"
        elif to != BROADCAST and to not in self._roster:
            reason = "unknown_peer"
        if reason is None and self._own is not None:
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
            key = (
                self._keys.broadcast(self.uav)
                if to == BROADCAST
                else self._keys.inbox(to, self.uav)
            )
            try:
                self._mesh.put(key, msg, block=True)
            except MeshError as exc:
                reason = "closed" if isinstance(exc, MeshClosed) else "put_failed"
            else:
                self.stats.sent += 1
                return MsgRef(sender=self.uav, seq=msg.h.seq, to=to)
        self.stats.dropped[reason or "put_failed"] += 1
        log.debug("%s -> %s: message dropped (%s)", self.uav, to, reason)
        return None

    # -- receiving --------------------------------------------------------------------------

    async def collect_inbox(
        self,
        expect: Iterable[MsgRef] = (),
        timeout_s: float = 1.0,
        *,
        max_round: int | None = None,
    ) -> list[InboxMessage]:
        """Wait (at most ``timeout_s``) for every expected message, then return the accepted
        messages of rounds up to ``max_round`` (later ones stay queued), sorted by
        (sender, seq). Missing ones are counted."""
        return await self.inbox.collect(expect, timeout_s, max_round=max_round)

    def _refusal(self, key: str, msg: InboxMessage, broadcast: bool) -> str | None:
        """Why ``msg`` on ``key`` is refused by the checks that need neither its signature
        nor any state change, or None. "own" means our own broadcast (not counted)."""
        sender = msg.h.sender
        expected_key = (
            self._keys.broadcast(sender) if broadcast else self._keys.inbox(self.uav, sender)
        )
        if key != expected_key:
            return "spoofed_sender"
        if msg.to != (BROADCAST if broadcast else self.uav):
            return "wrong_recipient"
        if sender == self.uav:
            return "own"
        if sender not in self._roster:
            return "unknown_sender"
        if self.inbox.too_old(msg.round):
            return "no_own_position"  # what collect would say: nothing to judge its reach by
        return self.inbox.admit(msg) or self._replay.would_refuse(
            msg.h, stream="broadcast" if broadcast else "inbox"
        )

    def _precheck(self, key: str, msg: InboxMessage, broadcast: bool) -> bool:
        """Before the signature is verified (``Mesh.subscribe(precheck=)``): everything
        cheap, so a flood of messages that could not be accepted costs no verification."""
        why = self._refusal(key, msg, broadcast)
        if why is None:
            return True
        if why != "own":
            self.inbox.reject(why, key)
        return False

    def _precheck_inbox(self, key: str, msg: InboxMessage) -> bool:
        return self._precheck(key, msg, False)

    def _precheck_broadcast(self, key: str, msg: InboxMessage) -> bool:
        return self._precheck(key, msg, True)

    def _precheck_beacon(self, key: str, beacon: StateBeacon) -> bool:
        """The beacon checks that need no signature and change nothing; the rest (replay
        order, motion) run on the verified beacon."""
        if not self._beacon_from_a_known_peer(key, beacon):
            return False
        if self._replay.would_refuse(beacon.h, stream="beacon") is not None:
            self.inbox.reject("stale_beacon", key)
            return False
        return True

    def _beacon_from_a_known_peer(self, key: str, beacon: StateBeacon) -> bool:
        """Another UAV's beacon on its own key, from a peer we know (refusals counted);
        our own beacon, delivered locally, is silently not one."""
        if beacon.uav == self.uav:
            return False
        if key != self._keys.state(beacon.uav) or beacon.h.sender != beacon.uav:
            self.inbox.reject("spoofed_beacon", key)
            return False
        known = self.limits.known_peers
        if known is not None and beacon.uav not in known:
            self.inbox.reject("unknown_peer", key)
            return False
        return True

    def _accept(self, key: str, msg: InboxMessage, *, broadcast: bool) -> None:
        sender = msg.h.sender
        expected_key = (
            self._keys.broadcast(sender) if broadcast else self._keys.inbox(self.uav, sender)
        )
        if key != expected_key:
            self.inbox.reject("spoofed_sender", key)
        elif msg.to != (BROADCAST if broadcast else self.uav):
            self.inbox.reject("wrong_recipient", key)
        elif sender == self.uav:
            return  # our own broadcast, delivered locally
        elif sender not in self._roster:
            self.inbox.reject("unknown_sender", key)
        elif (full := self.inbox.admit(msg)) is not None:
            self.inbox.reject(full, key)
        elif why := self._replay.check(
            msg.h,
            authenticated=self._mesh.authenticated,
            stream="broadcast" if broadcast else "inbox",
        ):
            self.inbox.reject(why, key)
        else:
            self.inbox.offer(msg)

    def _on_inbox(self, item: tuple[str, InboxMessage]) -> None:
        self._accept(*item, broadcast=False)

    def _on_broadcast(self, item: tuple[str, InboxMessage]) -> None:
        self._accept(*item, broadcast=True)

    def _on_beacon(self, item: tuple[str, StateBeacon]) -> bool:
        """Latest wins by (epoch, seq); the key, the payload and the header must agree, and
        the claimed position must be physically plausible."""
        key, beacon = item
        if not self._beacon_from_a_known_peer(key, beacon):
            return False
        implausible = self._implausible(beacon)
        if implausible is not None:
            self.inbox.reject(implausible, key)
            return False
        why = self._replay.check(beacon.h, authenticated=self._mesh.authenticated, stream="beacon")
        if why is not None:
            self.inbox.reject("stale_beacon" if why == "replay" else why, key)
            return False
        self._beacons[beacon.uav] = beacon
        self._beacon_seen[beacon.uav] = time.monotonic()
        self.inbox.notify()
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
        if self.inbox.too_far_ahead(beacon.round):
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
            self.inbox.reject("unknown_peer_token", key)
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
            self.inbox.forget(uav)
        self.inbox.notify()


__all__ = ["PeerLimits", "PeerLink", "PeerStats"]
