"""The receive side every PeerChannel shares: acceptance, the reach rule, waiting, ordering.

Both the Zenoh ``PeerLink`` and the in-memory channel feed arriving messages into one
``Inbox`` after their transport checks (key vs sender, recipient, roster, replay), so what a
UAV accepts and when is written once:

* a message enters the round after the one it was sent in (``collect(max_round=t-1)``);
* it is accepted only if it *reaches* this UAV: the routing rule (``set_routing``) applied
  to the sender's role, this UAV's role and the distance between the sender's position in
  the message and this UAV's own position in the round the message was sent (remembered
  from its beacon). Lockstep simulation therefore judges range on the same frozen positions
  in every run, without any sender waiting for anyone's beacon;
* expected messages (the simulator's manifest) are waited for, bounded; missing ones are
  counted; the result is sorted by (sender, sequence).

Every check drops and counts instead of raising: a bad message never stops the round loop.
The queue is bounded (``PeerLimits``: count, per sender, bytes, rounds ahead), so a flood of
well-formed messages cannot grow it: defence in depth behind TLS, ACL and signatures.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections import Counter
from collections.abc import Callable, Collection, Iterable
from dataclasses import dataclass, field

import msgspec

from aeroweaver_edge.contracts.defaults import COMM_RADIUS_M
from aeroweaver_edge.contracts.ports import Reach
from aeroweaver_edge.contracts.wire import InboxMessage, MsgRef, Vec3

log = logging.getLogger(__name__)

# Drops that are the radio model at work (the routing rule) or the end of an episode (a
# message sent in its last round has no next round to enter), not refusals of bad input:
# left out of security counts.
RADIO_DROPS = frozenset({"out_of_range", "episode_ended"})
ARRIVED_MEMORY = 4096  # (sender, seq) pairs remembered so an early arrival is not "missing"
POSITION_MEMORY = 16  # rounds of own positions kept for judging late messages


@dataclass(frozen=True)
class PeerLimits:
    """Receive-side bounds of one UAV's peer channel. ``None`` turns a check off."""

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
    missing: int = 0  # expected messages that had not arrived when collect gave up


def within(radius_m: float = COMM_RADIUS_M) -> Reach:
    """The routing rule with no task: everyone reaches everyone within the radius."""

    def rule(sender_role: str, receiver_role: str, distance_m: float) -> bool:
        return distance_m <= radius_m

    return rule


class Inbox:
    """One UAV's queue of received messages and the rule that decides which count."""

    def __init__(
        self, uav: str, comm_radius_m: float = COMM_RADIUS_M, limits: PeerLimits | None = None
    ) -> None:
        if comm_radius_m <= 0:
            raise ValueError(f"comm_radius_m must be > 0, got {comm_radius_m}")
        self.uav = uav
        self.limits = limits or PeerLimits()
        self.stats = PeerStats()
        self.role = ""
        self.reach: Reach = within(comm_radius_m)
        self._positions: dict[int, Vec3] = {}
        self._ended_round: int | None = None  # last round of the previous episode
        self._pending: list[InboxMessage] = []
        self._pending_bytes: dict[tuple[str, int], int] = {}  # (sender, seq) -> encoded size
        self._arrived: dict[tuple[str, int], None] = {}  # insertion-ordered, bounded
        self._waiters: set[asyncio.Future[None]] = set()

    def set_routing(self, role: str, reach: Reach) -> None:
        self.role = role
        self.reach = reach

    def note_position(self, round: int, pos: Vec3) -> None:
        """This UAV's own position in ``round`` (from its beacon). Own rounds only go
        forward, so an earlier one means the round clock restarted (the next episode): the
        old episode's positions are forgotten. Kept, they would outnumber the new ones and
        the oldest-round eviction would drop the new episode's first rounds, so every
        message of those rounds failed the reach rule ("no_own_position")."""
        newest = self.round
        if newest is not None and round < newest:
            self._ended_round = newest
            self._positions.clear()
        self._positions[round] = pos
        while len(self._positions) > POSITION_MEMORY:
            del self._positions[min(self._positions)]

    @property
    def round(self) -> int | None:
        """This UAV's latest round (from its own beacons), or None before the first."""
        return max(self._positions) if self._positions else None

    def too_far_ahead(self, round_: int) -> bool:
        """A round beyond the window this UAV may already hear of (a forged or stale one)."""
        ahead, own = self.limits.future_rounds, self.round
        return ahead is not None and own is not None and round_ > own + ahead

    def too_old(self, round_: int) -> bool:
        """A round older than every own position kept: its reach can never be judged.

        Rounds restart at 0 with each episode, and a peer may start the next episode (and
        send in its first rounds) before this UAV has published its own first beacon of it.
        Such a message is not old but early: its reach is judged at ``collect``, once our
        position in its round is known. So the first rounds a peer may be ahead by
        (``future_rounds``, the window ``too_far_ahead`` allows) are never too old here;
        refusing them on arrival made acceptance depend on which of two daemons ran first,
        and repeated lockstep runs of one seed diverged at episode starts."""
        if not self._positions or round_ >= min(self._positions):
            return False
        return round_ > (self.limits.future_rounds or 0)

    def _ahead_reason(self, round_: int) -> str:
        """Why a message too far ahead is dropped: sent in the last two rounds of the episode
        that just ended (it has no next round to enter), or forged or stale. The window is
        narrow so that a peer cannot hide stale rounds among the radio drops."""
        last = self._ended_round
        ended = last is not None and last - 1 <= round_ <= last
        return "episode_ended" if ended else "future_round"

    def forget(self, sender: str) -> None:
        """The sender's session ended: its sequence numbers restart, so an old (sender,
        seq) is no longer an arrival."""
        self._arrived = {k: None for k in self._arrived if k[0] != sender}

    def reject(self, reason: str, what: str) -> None:
        self.stats.rejected[reason] += 1
        log.debug("%s: rejected %s (%s)", self.uav, what, reason)

    @property
    def pending(self) -> int:
        """Messages queued for a later round."""
        return len(self._pending)

    def drop_pending(self) -> None:
        """Forget every queued message (a harness standing in for collected rounds)."""
        self._pending.clear()
        self._pending_bytes.clear()

    def admit(self, msg: InboxMessage) -> str | None:
        """Why ``msg`` cannot be queued (too far ahead, buffer full), or None if it can.
        Checked before the replay filter, so a refused message does not consume its
        sequence number."""
        if self.too_far_ahead(msg.round):
            return self._ahead_reason(msg.round)
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

    def offer(self, msg: InboxMessage) -> None:
        """A message that passed the transport's checks and ``admit``: queue it and wake
        waiters."""
        self.stats.received += 1
        self._pending.append(msg)
        self._pending_bytes[(msg.h.sender, msg.h.seq)] = len(msgspec.msgpack.encode(msg))
        self._arrived[(msg.h.sender, msg.h.seq)] = None
        if len(self._arrived) > ARRIVED_MEMORY:
            del self._arrived[next(iter(self._arrived))]
        self.notify()

    def _reaches(self, msg: InboxMessage) -> str | None:
        """Why ``msg`` does not reach this UAV, or None if it does."""
        own = self._positions.get(msg.round)
        if own is None:
            return "no_own_position"
        if msg.sender_pos is None or not all(math.isfinite(x) for x in msg.sender_pos):
            return "no_sender_position"
        d = math.hypot(own[0] - msg.sender_pos[0], own[1] - msg.sender_pos[1])
        return None if self.reach(msg.sender_role, self.role, d) else "out_of_range"

    async def collect(
        self,
        expect: Iterable[MsgRef] = (),
        timeout_s: float = 1.0,
        *,
        max_round: int | None = None,
    ) -> list[InboxMessage]:
        want = {(ref.sender, ref.seq) for ref in expect}
        if not await self.wait_until(lambda: want <= self._arrived.keys(), timeout_s):
            missing = sorted(want - self._arrived.keys())
            self.stats.missing += len(missing)
            log.info("%s: %d expected message(s) missing: %s", self.uav, len(missing), missing)
        ready: list[InboxMessage] = []
        keep: list[InboxMessage] = []
        if max_round is None:
            ready = self._pending
        else:
            # Kept for a later round only if that round is near: leftovers of an earlier
            # episode (rounds restart at 0) or forged far-future rounds are dropped here.
            ahead = self.limits.future_rounds
            horizon = max_round + 1 + ahead if ahead is not None else None
            for m in self._pending:
                if m.round <= max_round:
                    ready.append(m)
                elif horizon is None or m.round <= horizon:
                    keep.append(m)
                else:
                    self.reject(self._ahead_reason(m.round), f"{m.h.sender}#{m.h.seq}")
        self._pending = keep
        kept = {(m.h.sender, m.h.seq) for m in keep}
        self._pending_bytes = {k: v for k, v in self._pending_bytes.items() if k in kept}
        out = []
        for m in ready:
            why = self._reaches(m)
            if why is None:
                out.append(m)
            else:
                self.reject(why, f"{m.h.sender}#{m.h.seq}")
        out.sort(key=lambda m: (m.h.sender, m.h.seq))
        return out

    # -- waiting ----------------------------------------------------------------------------

    def notify(self) -> None:
        for fut in self._waiters:
            if not fut.done():
                fut.set_result(None)
        self._waiters.clear()

    async def wait_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
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


__all__ = ["RADIO_DROPS", "Inbox", "PeerLimits", "PeerStats", "within"]
