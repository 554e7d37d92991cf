"""The neighbourhood: which K records of a (task, role) group a state retrieves.

Retrieval policy over the group index (``memory.index`` scores; this picks): the K most
similar records, best first, with peers that hold more of the group than this daemon
capped to ``max_sender_share`` of the places (the defence against a peer flooding the
neighbourhood; none in a balanced, honest swarm, where this is exactly the uncapped pick).
Kept apart from persistence (``memory.store``) and from what the neighbourhood is used for
(``estimators``).
"""

from __future__ import annotations

from dataclasses import dataclass

from aeroweaver_edge.agent.memory.index import (
    SMALL_GROUP,
    Group,
    Selection,
    select_indexed,
    select_python,
    select_scan,
    values,
)
from aeroweaver_edge.agent.memory.records import LOCAL, Neighbour


@dataclass
class Retrieval:
    """How a memory picks neighbourhoods: ``k`` places, a sender cap, ended episodes only."""

    k: int
    max_sender_share: float
    finalised_only: bool = False

    def select(self, group: Group, tokens: frozenset[str]) -> Selection:
        """Positions of the neighbourhood (best first) and their Jaccard similarities."""
        heavy = self.heavy_origins(group)
        if not heavy:
            return self.ordered(group, tokens, self.k)
        # The capped pick walks the best-first order until K places are filled. Every
        # selection returns a prefix of one total order (similarity, then recency), so
        # a prefix that fills K gives what the whole order would: widen it only when the
        # caps left places open (a late joiner, whose peers all hold more than it does,
        # would otherwise score the whole group every round).
        k = 4 * self.k
        while True:
            pos, sim = self.ordered(group, tokens, k)
            capped = self.capped(group, pos, sim, heavy)
            if len(capped[0]) >= self.k or len(pos) < k:
                return capped
            k *= 4

    def ordered(self, group: Group, tokens: frozenset[str], k: int) -> Selection:
        """The first ``k`` of the group's best-first order: plain Python for small groups
        (no numpy import in a small daemon), the indexed numpy pick above; the same
        records either way."""
        if len(group) <= SMALL_GROUP:
            return select_python(group, tokens, k, self.finalised_only)
        return select_indexed(group, tokens, k, self.finalised_only)

    def whole_group(self, group: Group, tokens: frozenset[str]) -> Selection:
        """The neighbourhood found by scoring every record and walking the whole
        best-first order under the caps: no index, no early stop. What ``select`` must
        equal; for tests and benchmarks."""
        pos, sim = select_scan(group, tokens, len(group), self.finalised_only)
        heavy = self.heavy_origins(group)
        if heavy:
            return self.capped(group, pos, sim, heavy)
        return pos[: self.k], sim[: self.k]

    def heavy_origins(self, group: Group) -> set[int]:
        """Peers (origin ids) with more live records in ``group`` than this daemon's own."""
        if self.max_sender_share >= 1.0:
            return set()
        own_id = group.origin_ids.get(LOCAL)
        own = group.origin_count[own_id] if own_id is not None else 0
        return {
            oid for oid, n in enumerate(group.origin_count) if oid != own_id and n > max(own, 0)
        }

    def capped(self, group: Group, pos: list[int], sim: list[float], heavy: set[int]) -> Selection:
        """The best-first ``pos`` cut to K places with each heavy origin at most its cap."""
        cap = max(1, int(self.max_sender_share * self.k))
        taken: dict[int, int] = {}
        out_pos: list[int] = []
        out_sim: list[float] = []
        for i, s in zip(pos, sim, strict=True):
            oid = group.origin[i]
            if oid in heavy:
                if taken.get(oid, 0) >= cap:
                    continue
                taken[oid] = taken.get(oid, 0) + 1
            out_pos.append(i)
            out_sim.append(s)
            if len(out_pos) >= self.k:
                break
        return out_pos, out_sim


def neighbours(group: Group, pos: list[int], sim: list[float]) -> list[Neighbour]:
    """The selected records as ``Neighbour`` rows (inspection, tests, the console)."""
    return [
        Neighbour(
            group.keys[i][1:],
            group.skills[group.skill[i]],
            v,
            s,
            group.seq[i],
            group.keys[i][0],
        )
        for i, s, v in zip(pos, sim, values(group, pos), strict=True)
    ]
