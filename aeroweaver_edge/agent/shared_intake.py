"""Peers' shared experience between its arrival and its storage in this daemon's memory.

Retrieval breaks similarity ties by the order records were stored, and the mesh delivers
several peers' records in whatever order their streams interleave: differently in an
in-process swarm and with one process per daemon, and from one run to the next. So a record
is *taken* here when it arrives (checked, deduplicated, counted per run and episode) and
*stored* at the start of the daemon's next round, all pending records at once in one
canonical order (run, episode, uav, round). With the orchestration's barrier between
episodes (``orchestration/barrier.py``, which waits for the taken counts) every run of a
seed stores the same memory in the same order, whatever the process layout.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from typing import TYPE_CHECKING

from aeroweaver_edge.wire import ExperienceRecord

if TYPE_CHECKING:
    from aeroweaver_edge.agent.memory import AsyncExperienceMemory

log = logging.getLogger(__name__)

RecordKey = tuple[str, str, int, int]  # (run, uav, episode, round)
MAX_PENDING = 65_536  # records waiting for the next round (a flood is refused, counted)
MAX_PENDING_PER_SENDER = 4096  # of those, one peer's (a flooding peer crowds out no other)
MAX_EPISODES = 64  # (run, episode) tallies kept
MAX_TAKEN = 65_536  # records remembered per tally


def _version(rec: ExperienceRecord) -> tuple[bool, int, int]:
    return rec.final, rec.h.epoch, rec.h.seq


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
        self._taken: OrderedDict[tuple[str, int], set[RecordKey]] = OrderedDict()
        self.refused = 0  # not a peer's own record on its own key, or over the bound
        self.stored = 0

    def offer(self, key: str, rec: ExperienceRecord, role: str | None) -> bool:
        """Take ``rec`` (published on ``key``) if it is a same-role peer's own record;
        returns whether it counts as taken (new, or a newer version of one taken)."""
        if role is None or rec.role != role or rec.uav == self.uav:
            return False  # not for us (another role, no mission, our own echo)
        if not rec.uav == rec.h.sender == key.split("/")[-2]:
            self.refused += 1  # a UAV shares only its own experience, on its own key
            return False
        k: RecordKey = (rec.run, rec.uav, rec.episode, rec.round)
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
        seen = self._taken.setdefault((rec.run, rec.episode), set())
        self._taken.move_to_end((rec.run, rec.episode))
        while len(self._taken) > MAX_EPISODES:
            self._taken.popitem(last=False)
        if len(seen) < MAX_TAKEN:
            seen.add(k)
        return True

    def taken(self, run: str, episode: int) -> int:
        """Distinct peers' records of ``run``'s ``episode`` taken so far."""
        return len(self._taken.get((run, episode), ()))

    @property
    def pending(self) -> int:
        return len(self._pending)

    async def store(self, memory: AsyncExperienceMemory) -> int:
        """Store every pending record in canonical order; returns how many changed memory."""
        order = sorted(self._pending, key=lambda k: (k[0], k[2], k[1], k[3]))  # run, ep, uav, rnd
        batch = [self._pending[k] for k in order]
        self._pending.clear()
        self._per_sender.clear()
        changed = 0
        for rec in batch:
            changed += await memory.ingest(rec)
        self.stored += changed
        return changed


__all__ = ["SharedIntake"]
