"""Shared swarm memory inside an episode (``[agent] share_every = "round"``).

Why: shared only as an episode ends, a UAV retrieves only its own records during the
episode; the paper's experience "accumulates across decision rounds through shared swarm
memory". Here a daemon publishes each record once its round is rewarded; same-role peers
store it before their next decision (``SharedIntake``: the world names the peers to wait
for, so the round it becomes visible does not depend on timing or process layout).

A daemon also serves its most recent records (``ExperienceBatch``, at most
``MAX_BATCH_RECORDS`` and one payload) on its experience key as a queryable, so a daemon
that restarts or joins late fetches its role's recent experience from its peers. Fetched
records go through the same intake (signature, sender, per-sender caps) as published ones.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import OrderedDict, deque
from typing import TYPE_CHECKING

import msgspec

from aeroweaver_edge.agent.memory.shared_intake import SharedIntake
from aeroweaver_edge.contracts.wire import (
    MAX_BATCH_RECORDS,
    MAX_HELD_REWARDS,
    MAX_PAYLOAD_BYTES,
    ExperienceBatch,
    ExperienceRecord,
    HeaderFactory,
    Keys,
)
from aeroweaver_edge.mesh.session import MeshError

if TYPE_CHECKING:
    from aeroweaver_edge.mesh.session import Mesh, Queryable

log = logging.getLogger(__name__)

BATCH_BYTES = MAX_PAYLOAD_BYTES - 4096  # room for the batch's header and framing
FETCH_TIMEOUT_S = 1.0
WAIT_S = 2.0
"""Longest wait at a round's start for the peers' records the world announced (at most a
quarter of the round's deadline): they are published as the previous round's reward
arrives, milliseconds before the round starts; a peer that died after its command costs
this much of the round, counted and logged."""


def wait_bound(deadline_s: float) -> float:
    return min(WAIT_S, deadline_s / 4)


class RoundSharing:
    """One daemon's side of per-round sharing: what it serves, what it waits for."""

    def __init__(
        self,
        mesh: Mesh,
        keys: Keys,
        uav: str,
        headers: HeaderFactory,
        intake: SharedIntake,
        gamma: float = 0.95,
    ) -> None:
        self.mesh, self.keys, self.uav, self.gamma = mesh, keys, uav, gamma
        self.headers = headers
        self.intake = intake
        self.arrived = asyncio.Event()  # set by the daemon's experience pump on every burst
        self._served: OrderedDict[tuple[str, int, int], tuple[ExperienceRecord, int]] = (
            OrderedDict()
        )  # (run, episode, round) -> newest version, encoded size
        self._batch: ExperienceBatch | None = None
        self._queryable: Queryable | None = None
        self._rewards: deque[tuple[int, int, float]] = deque(maxlen=MAX_HELD_REWARDS)
        self.wait_timeouts = 0  # rounds whose expected peers' records did not all arrive
        self.fetched = 0  # records taken from peers' queryables

    def start(self) -> None:
        self._queryable = self.mesh.declare_queryable(self.keys.experience(self.uav), self.batch)

    async def aclose(self) -> None:
        if self._queryable is not None:
            await self._queryable.aclose()
            self._queryable = None

    def note_reward(self, episode: int, round: int, reward: float) -> None:
        """A reward of this daemon's: carried by its next published record if its round
        has no record of its own (held)."""
        self._rewards.append((episode, round, reward))

    def held_rewards(self, episode: int, round: int) -> list[tuple[int, float]]:
        """The rewards of ``episode``'s rounds before ``round`` not yet carried (the rounds
        this daemon held since its previous record); forgets them and every older one."""
        out = [(u, r) for e, u, r in self._rewards if e == episode and u < round]
        kept = [(e, u, r) for e, u, r in self._rewards if (e, u) > (episode, round)]
        self._rewards.clear()
        self._rewards.extend(kept)
        return out

    def published(self, rec: ExperienceRecord) -> None:
        """Note an own record just published (in flight or finalised) for the queryable.
        An in-flight record's reward extends the served earlier records of its episode as
        it extended them in memory, so a late joiner gets returns as they stand."""
        key = (rec.run, rec.episode, rec.round)
        rewards = sorted(rec.held_rewards) + (
            [(rec.round, rec.reward)] if rec.reward is not None else []
        )
        if not rec.final and rewards:
            for (run, episode, rnd), (old, n) in list(self._served.items()):
                if (run, episode) != key[:2] or rnd >= rec.round or old.final:
                    continue
                ret = old.ret
                for u, r in rewards:
                    if rnd < u:
                        ret = (ret or 0.0) + self.gamma ** (u - rnd) * r
                self._served[(run, episode, rnd)] = (msgspec.structs.replace(old, ret=ret), n)
        self._served.pop(key, None)
        self._served[key] = (rec, len(msgspec.msgpack.encode(rec)))
        while len(self._served) > MAX_BATCH_RECORDS:
            self._served.popitem(last=False)
        self._batch = None

    def batch(self) -> ExperienceBatch | None:
        """The queryable's answer: the newest records that fit one payload (None: none)."""
        if not self._served:
            return None
        if self._batch is None:
            h = self.headers.next()
            picked: list[ExperienceRecord] = []
            size = 0
            for rec, n in reversed(self._served.values()):
                if size + n > BATCH_BYTES:
                    break
                picked.append(msgspec.structs.replace(rec, h=h))
                size += n
            self._batch = ExperienceBatch(h=h, uav=self.uav, records=picked[::-1])
        return self._batch

    async def fetch(self, role: str | None) -> int:
        """Ask every peer's queryable for its recent records; offer them to the intake
        (stored at the next round start). Returns records taken."""
        try:
            replies = await self.mesh.get(
                self.keys.experience("*"), ExperienceBatch, timeout_s=FETCH_TIMEOUT_S
            )
        except MeshError:
            return 0
        taken = 0
        for key, b in sorted(replies, key=lambda kv: kv[0]):
            if not b.uav == b.h.sender == key.split("/")[-2]:
                self.intake.refused += 1
                continue
            taken += sum(self.intake.offer(key, rec, role, fetched=True) for rec in b.records)
        self.fetched += taken
        log.info("%s: fetched %d records of role %s from peers", self.uav, taken, role)
        return taken

    async def wait_for(self, run: str, episode: int, round: int, peers: tuple[str, ...],
                       bound_s: float) -> bool:  # fmt: skip
        """Wait (bounded) until every peer in ``peers`` has published its record of
        ``round``; False (counted) if the bound passed first."""
        deadline = time.monotonic() + bound_s

        def missing() -> list[str]:
            return [p for p in peers if not self.intake.arrived(run, p, episode, round)]

        while missing():
            left = deadline - time.monotonic()
            if left <= 0:
                self.wait_timeouts += 1
                log.warning(
                    "%s: experience of round %d/%d from %s did not arrive in %.1f s",
                    self.uav, episode, round, ", ".join(missing()), bound_s,
                )  # fmt: skip
                return False
            self.arrived.clear()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(left):
                    await self.arrived.wait()
        return True


__all__ = ["RoundSharing"]
