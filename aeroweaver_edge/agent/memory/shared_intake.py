"""Peers' shared experience between its arrival and its storage in this daemon's memory.

Retrieval breaks similarity ties by the order records were stored, and the mesh delivers
several peers' records in whatever order their streams interleave: differently in an
in-process swarm and with one process per daemon, and from one run to the next. So a record
is *taken* here when it arrives (checked, deduplicated, counted per run and episode) and
*stored* at the start of the daemon's next round, all pending records at once in one
canonical order (run, episode, uav, round). With the orchestration's barrier between
episodes (``orchestration/barrier.py``) every run of a seed stores the same memory in the
same order, whatever the process layout. The barrier waits for the *received* counts:
every peer's finalised record, whatever its role. A UAV reassigned mid-episode publishes
records of two roles and its peers take those of their current role only, so counts of
taken records cannot be checked against what was published without knowing every role
at every arrival; that every record arrived can, and implies every same-role one was taken.

Shared per round (``[agent] share_every = "round"``), a daemon also publishes each record as
it happens, with its round's reward; the world tells each UAV which same-role peers publish
one in a round (``SimPerception.expected_experience``), the daemon waits until they
``arrived`` and stores them before its next decision: a record of round t is retrieved by
every same-role peer from round t+1 on, whatever the process layout. Such an in-flight record
also extends the returns of that peer's earlier in-flight records (``credit_peer``); only
finalised records count as taken for the barrier between episodes.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from typing import TYPE_CHECKING

from aeroweaver_edge.contracts.wire import ExperienceRecord

if TYPE_CHECKING:
    from aeroweaver_edge.agent.memory.async_memory import AsyncExperienceMemory

log = logging.getLogger(__name__)

RecordKey = tuple[str, str, int, int]  # (run, uav, episode, round)
MAX_PENDING = 65_536  # records waiting for the next round (a flood is refused, counted)
MAX_PENDING_PER_SENDER = 4096  # of those, one peer's (a flooding peer crowds out no other)
MAX_EPISODES = 64  # (run, episode) tallies kept
MAX_TAKEN = 65_536  # records remembered per tally


def _version(rec: ExperienceRecord) -> tuple[bool, int, int]:
    return rec.final, rec.h.epoch, rec.h.seq


Tallies = OrderedDict[tuple[str, int], set[RecordKey]]  # (run, episode) -> records counted


def _count(tallies: Tallies, k: RecordKey) -> bool:
    """Count ``k`` in its (run, episode) tally, forgetting the oldest tallies past
    ``MAX_EPISODES``; whether it is new there."""
    tally = (k[0], k[2])
    seen = tallies.setdefault(tally, set())
    tallies.move_to_end(tally)
    while len(tallies) > MAX_EPISODES:
        tallies.popitem(last=False)
    if k in seen or len(seen) >= MAX_TAKEN:
        return False
    seen.add(k)
    return True


class SharedIntake:
    """Takes same-role peers' records as they arrive; stores them in canonical order."""

    def __init__(
        self,
        uav: str,
        max_pending: int = MAX_PENDING,
        max_per_sender: int = MAX_PENDING_PER_SENDER,
    ) -> None:
        self.uav = uav
        self.max_pending = max_pending
        self.max_per_sender = max_per_sender
        self._pending: dict[RecordKey, ExperienceRecord] = {}
        self._per_sender: dict[str, int] = {}  # pending records by sender
        self._taken: Tallies = OrderedDict()
        self._arrived: OrderedDict[RecordKey, None] = OrderedDict()  # authentic, any role
        # authentic finalised peers' records per (run, episode), any role: the barrier's count
        self._received: Tallies = OrderedDict()
        self._grown: set[tuple[str, int]] = set()  # received counts grown since ``grown``
        self._fetched: set[RecordKey] = set()  # pending records fetched from a queryable
        self.refused = 0  # not a peer's own record on its own key, or over the bound
        self.stored = 0

    def offer(
        self, key: str, rec: ExperienceRecord, role: str | None, *, fetched: bool = False
    ) -> bool:
        """Take ``rec`` (published on ``key``) if it is a same-role peer's own record;
        returns whether it counts as taken (new, or a newer version of one taken).
        ``fetched``: from a peer's queryable (its return is already extended; it credits
        nothing and is not a round's expected record)."""
        if rec.uav == self.uav:
            return False  # our own echo
        if not rec.uav == rec.h.sender == key.split("/")[-2]:
            self.refused += 1  # a UAV shares only its own experience, on its own key
            return False
        k: RecordKey = (rec.run, rec.uav, rec.episode, rec.round)
        if rec.final:
            self._receive(k)
        elif not fetched:
            self._arrived[k] = None
            self._arrived.move_to_end(k)
            while len(self._arrived) > MAX_TAKEN:
                self._arrived.popitem(last=False)
        if role is None or rec.role != role:
            return False  # not for us (another role, no mission)
        old = self._pending.get(k)
        if old is not None and _version(old) >= _version(rec):
            return False
        if old is None and (
            len(self._pending) >= self.max_pending
            or self._per_sender.get(rec.uav, 0) >= self.max_per_sender
        ):
            self.refused += 1
            return False
        if old is None:
            self._per_sender[rec.uav] = self._per_sender.get(rec.uav, 0) + 1
        self._pending[k] = rec
        if fetched:
            self._fetched.add(k)
        else:
            self._fetched.discard(k)
        if not rec.final:
            return True  # counted by the barrier once its finalised version comes
        _count(self._taken, k)
        return True

    def _receive(self, k: RecordKey) -> None:
        if _count(self._received, k):
            self._grown.add((k[0], k[2]))
            if len(self._grown) > MAX_EPISODES:  # only tallies still kept can be due
                self._grown.intersection_update(self._received)

    def received(self, run: str, episode: int) -> int:
        """Distinct peers' finalised records of ``run``'s ``episode`` received, any role."""
        return len(self._received.get((run, episode), ()))

    def grown(self, run: str) -> list[int]:
        """The episodes of ``run`` whose received count grew since the last call (their
        tally is due); forgets the rest."""
        episodes = sorted(e for r, e in self._grown if r == run and (r, e) in self._received)
        self._grown.clear()
        return episodes

    def arrived(self, run: str, uav: str, episode: int, round: int) -> bool:
        """Whether ``uav``'s in-flight record of that round has arrived (whatever its role)."""
        return (run, uav, episode, round) in self._arrived

    def taken(self, run: str, episode: int) -> int:
        """Distinct peers' finalised records of ``run``'s ``episode`` taken so far."""
        return len(self._taken.get((run, episode), ()))

    @property
    def pending(self) -> int:
        return len(self._pending)

    async def store(self, memory: AsyncExperienceMemory) -> int:
        """Store every pending record in canonical order; returns how many changed memory."""
        order = sorted(self._pending, key=lambda k: (k[0], k[2], k[1], k[3]))  # run, ep, uav, rnd
        batch = [(self._pending[k], k in self._fetched) for k in order]
        self._pending.clear()
        self._per_sender.clear()
        self._fetched.clear()
        changed = await memory.store_peers(batch) if batch else 0
        self.stored += changed
        return changed


__all__ = ["SharedIntake"]
