"""Retrieval of experience memory: the neighbourhood of a state (DESIGN §5, agent.memory).

One ``Group`` per (task, role): an in-memory inverted index over state tokens, position i
= the group's i-th record in stored order (``seq``), loaded from the table on first use and
kept in sync on every write. A position never moves: an evicted record is only marked
``gone`` (never eligible again) and the memory rebuilds a group once half of it is gone.

The neighbourhood is the top K eligible records by Jaccard overlap of token sets (overlap
> 0), best first, ties broken towards the newest (highest position). Three selections
compute exactly that, with the same float similarities ``c / (size + q - c)``:

``select_python``
    plain Python over the postings; for groups up to ``SMALL_GROUP`` (no numpy import).
``select_scan``
    numpy: one ``bincount`` over every posting of the query's tokens, then a threshold
    pick of the top K over the whole group. Kept as the reference
    (``ExperienceMemory.whole_group_neighbourhood``); the per-sender share cap walks a
    widening prefix of the order from the other two instead.
``select_indexed``
    numpy, for large groups. Overlaps are counted in ``uint8``/``uint16``: a token held by
    at least 1/16 of the group adds a cached dense 0/1 column (one vectorised add, no
    scatter), a rarer one increments its postings. Then a count bound prunes: a record
    with overlap c has Jaccard at most c / q (q = query tokens, as size >= c), so once K
    eligible records with overlap >= T give a K-th best similarity theta with
    (T - 1) / q < theta (compared in integers, exactly), no record below T can enter or
    tie; only the few records at or above T are scored. Same records, order and
    similarities as ``select_scan`` (tests compare them on random data with ties and
    evictions).
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any, Final

from aeroweaver_edge.agent.estimators import HorizonBook
from aeroweaver_edge.agent.memory.records import LOCAL, RunKey

if TYPE_CHECKING:
    import numpy as np

SMALL_GROUP: Final = 2048
"""Largest (task, role) group scored in plain Python; larger ones use numpy."""

DENSE_FRACTION: Final = 16
"""A token held by at least 1/DENSE_FRACTION of a group gets a dense 0/1 column (one byte
per record: adding it costs less than incrementing that many scattered positions)."""

WINDOW: Final = 3
"""Count levels one pass over the group collects while the threshold steps down."""

Selection = tuple[list[int], list[float]]  # positions best first, their similarities


class Group:
    """In-memory inverted index of one (task, role): position i = i-th record by seq."""

    __slots__ = (
        "book",
        "dead",
        "dense",
        "final",
        "gone",
        "keys",
        "origin",
        "origin_count",
        "origin_ids",
        "origins",
        "pos",
        "postings",
        "ret",
        "seq",
        "size",
        "skill",
        "skill_ids",
        "skills",
    )

    def __init__(self, book: HorizonBook | None = None) -> None:
        self.book = book  # an estimator's per-record bookkeeping (agent.estimators)
        self.seq = array("q")
        self.size = array("i")  # token-set size
        self.ret = array("d")  # NaN = no return yet
        self.final = array("b")
        self.skill = array("i")
        self.skills: list[str] = []
        self.skill_ids: dict[str, int] = {}
        self.postings: dict[str, array[int]] = {}
        self.pos: dict[RunKey, int] = {}
        self.keys: list[RunKey] = []
        self.origin = array("i")  # id into origins ("" = this daemon's own)
        self.origins: list[str] = []
        self.origin_ids: dict[str, int] = {}
        self.origin_count: list[int] = []  # live records per origin id
        self.dead = 0  # evicted positions (never eligible; the group is rebuilt when many)
        self.gone = array("b")  # 1 = evicted: excluded under every estimator
        # token -> [0/1 column (capacity >= len), postings already set in it]; built on
        # demand by ``select_indexed`` for frequent tokens, extended as the group grows.
        self.dense: dict[str, list[Any]] = {}

    def __len__(self) -> int:
        return len(self.seq)

    def remove(self, key: RunKey) -> None:
        """An evicted record: never eligible again (positions stay, so the order does)."""
        i = self.pos.pop(key, None)
        if i is not None:
            self.ret[i] = math.nan
            self.gone[i] = 1
            self.origin_count[self.origin[i]] -= 1
            self.dead += 1

    def add(
        self,
        key: RunKey,
        seq: int,
        tokens: Iterable[str],
        skill: str,
        ret: float | None,
        final: bool,
        origin: str = LOCAL,
        rewards: Iterable[tuple[int, float]] = (),
    ) -> None:
        """``rewards``: (round, reward) of the record's trajectory known now (the book's)."""
        i = len(self.seq)
        oid = self.origin_ids.get(origin)
        if oid is None:
            oid = self.origin_ids[origin] = len(self.origins)
            self.origins.append(origin)
            self.origin_count.append(0)
        self.origin.append(oid)
        self.origin_count[oid] += 1
        n_tokens = 0
        postings = self.postings
        for tok in tokens:
            plist = postings.get(tok)
            if plist is None:
                plist = postings[tok] = array("i")
            plist.append(i)
            n_tokens += 1
        sid = self.skill_ids.get(skill)
        if sid is None:
            sid = self.skill_ids[skill] = len(self.skills)
            self.skills.append(skill)
        self.seq.append(seq)
        self.size.append(n_tokens)
        self.ret.append(math.nan if ret is None else ret)
        self.final.append(1 if final else 0)
        self.gone.append(0)
        self.skill.append(sid)
        self.pos[key] = i
        self.keys.append(key)
        if self.book is not None:
            self.book.added(i, key, rewards)


def eligible(group: Group, i: int, finalised_only: bool) -> bool:
    """Whether record i may join a neighbourhood (has a value under the estimator)."""
    if group.gone[i]:
        return False  # evicted (a peer over its caps): never eligible again
    if group.book is not None:
        final = group.final[i] != 0
        return group.book.eligible(i, final) and (not finalised_only or final)
    return not math.isnan(group.ret[i]) and (not finalised_only or group.final[i] != 0)


def values(group: Group, pos: list[int]) -> list[float]:
    """The records' values for the estimator: returns, or the book's (agent.estimators)."""
    if group.book is None:
        return [group.ret[i] for i in pos]
    return group.book.values(pos, group.final)


def select_python(group: Group, tokens: frozenset[str], k: int, finalised_only: bool) -> Selection:
    n = len(group)
    everywhere = 0
    inter: dict[int, int] = {}
    for tok in tokens:
        plist = group.postings.get(tok)
        if plist is None:
            continue
        if len(plist) == n:
            everywhere += 1  # in every record: counted once, not per record
            continue
        for i in plist:
            inter[i] = inter.get(i, 0) + 1
    if n == 0 or (not inter and not everywhere):
        return [], []
    overlap = range(n) if everywhere else sorted(inter)
    q = len(tokens)
    scored = [
        (ci / (group.size[i] + q - ci), i)
        for i in overlap
        if eligible(group, i, finalised_only) and (ci := everywhere + inter.get(i, 0)) > 0
    ]
    # best first: similarity desc, then recency (position) desc; the first K of that
    # order are the top K by similarity with ties broken toward the newest.
    scored.sort(key=lambda x: (-x[0], -x[1]))
    best = scored[:k]
    return [i for _, i in best], [sim for sim, _ in best]


def _eligible_np(group: Group, cand: np.ndarray, finalised_only: bool) -> np.ndarray:
    """Boolean mask: which positions ``cand`` (an int array) are eligible."""
    import numpy as np

    final = np.frombuffer(group.final, dtype=np.int8)[cand] != 0
    if group.book is None:
        ok = ~np.isnan(np.frombuffer(group.ret, dtype=np.float64)[cand])
    else:
        count = np.frombuffer(group.book.count, dtype=np.int32)[cand]
        ok = (count >= group.book.h) | (final & (count > 0))
    if finalised_only:
        ok &= final
    if group.dead:
        ok &= np.frombuffer(group.gone, dtype=np.int8)[cand] == 0
    mask: np.ndarray = ok
    return mask


def _top(cand: np.ndarray, sim: np.ndarray, k: int) -> Selection:
    """The best K of ``cand`` (ascending positions) by similarity, ties to the newest."""
    import numpy as np

    if cand.size > k:
        kth = np.partition(sim, cand.size - k)[cand.size - k]  # k-th largest similarity
        above = np.flatnonzero(sim > kth)
        ties = np.flatnonzero(sim == kth)[-(k - above.size) :]  # newest of the tied
        keep = np.concatenate([above, ties])
    else:
        keep = np.arange(cand.size)
    # best first: similarity desc, then recency desc
    order = np.lexsort((-cand[keep], -sim[keep]))
    keep = keep[order]
    return [int(i) for i in cand[keep]], [float(x) for x in sim[keep]]


def select_scan(group: Group, tokens: frozenset[str], k: int, finalised_only: bool) -> Selection:
    import numpy as np

    n = len(group)
    # Tokens every record holds (task, role, fixed field names) add 1 to every overlap:
    # count them instead of concatenating n-long posting lists.
    everywhere = 0
    lists = []
    for tok in tokens:
        plist = group.postings.get(tok)
        if plist is None:
            continue
        if len(plist) == n:
            everywhere += 1
        else:
            lists.append(np.frombuffer(plist, dtype=np.int32))
    if n == 0 or (not lists and not everywhere):
        return [], []
    inter = np.full(n, everywhere, dtype=np.int64)
    if lists:
        inter += np.bincount(np.concatenate(lists), minlength=n)
    cand = np.flatnonzero(inter > 0)  # ascending position == ascending recency
    cand = cand[_eligible_np(group, cand, finalised_only)]
    if cand.size == 0:
        return [], []
    ci = inter[cand]
    sim = ci / (np.frombuffer(group.size, dtype=np.int32)[cand] + len(tokens) - ci)
    return _top(cand, sim, k)


def _dense(group: Group, tok: str, plist: array[int], n: int) -> np.ndarray:
    """The 0/1 column of ``tok`` over the group's first n positions (cached, extended)."""
    import numpy as np

    entry = group.dense.get(tok)
    if entry is None or len(entry[0]) < n:
        column = np.zeros(n + n // 4 + 1024, dtype=np.uint8)
        done = 0
        if entry is not None:
            column[: len(entry[0])] = entry[0]
            done = entry[1]
        entry = group.dense[tok] = [column, done]
    if entry[1] < len(plist):
        entry[0][np.frombuffer(plist, dtype=np.int32)[entry[1] :]] = 1
        entry[1] = len(plist)
    full: np.ndarray = entry[0]
    return full[:n]


def prepare(group: Group) -> int:
    """Build the dense columns of every frequent token now (a group loaded for a daemon's
    role), so the first queries do not pay for them. Returns the columns built."""
    n = len(group)
    built = 0
    for tok, plist in group.postings.items():
        if len(plist) < n and len(plist) * DENSE_FRACTION >= n:
            _dense(group, tok, plist, n)
            built += 1
    return built


def select_indexed(group: Group, tokens: frozenset[str], k: int, finalised_only: bool) -> Selection:
    import numpy as np

    n = len(group)
    q = len(tokens)
    everywhere = 0
    counted: list[tuple[int, str, array[int]]] = []
    for tok in tokens:
        plist = group.postings.get(tok)
        if plist is None:
            continue
        if len(plist) == n:
            everywhere += 1
        else:
            counted.append((len(plist), tok, plist))
    if n == 0 or (not counted and not everywhere):
        return [], []
    counts: np.ndarray = np.zeros(n, dtype=np.uint8 if len(counted) < 255 else np.uint16)
    for length, tok, plist in counted:
        if length * DENSE_FRACTION >= n:
            counts += _dense(group, tok, plist, n)
        else:
            counts[np.frombuffer(plist, dtype=np.int32)] += 1  # distinct positions
    for tok in [t for t in group.dense if len(group.postings[t]) * DENSE_FRACTION * 2 < n]:
        del group.dense[tok]  # became rare: its column is no longer worth its memory
    size = np.frombuffer(group.size, dtype=np.int32)
    # Overlap c = everywhere + counts. Records below a count threshold t have
    # c <= everywhere + t - 1, so Jaccard <= (everywhere + t - 1) / q.
    floor = 1 if everywhere == 0 else 0  # c >= 1: at least one shared token
    top = int(counts.max())
    t = max(floor, top)
    lo = n + 1  # ``pool``: the eligible records with counts >= lo (none yet)
    pool = sub = np.zeros(0, dtype=np.intp)
    while True:
        if t < lo:  # one pass over the group: a few levels at once while stepping down
            lo = max(floor, t - WINDOW)
            pool = np.flatnonzero(counts >= lo) if lo > 0 else np.arange(n)
            pool = pool[_eligible_np(group, pool, finalised_only)]
            sub = counts[pool]
        cand = pool[sub >= t] if t > lo else pool
        ci = everywhere + counts[cand].astype(np.int64)
        den = size[cand] + q - ci
        sim = ci / den
        if t <= floor:
            break  # every record with an overlap: exact by construction
        if cand.size < k:
            t -= 1
            continue
        j = int(np.argpartition(sim, cand.size - k)[cand.size - k])  # the K-th best
        best_c, best_d = int(ci[j]), int(den[j])
        # The largest t' whose excluded records all stay strictly below the K-th best,
        # in integers: everywhere + t' - 1 < best_c * q / best_d.
        need = -(-best_c * q // best_d) - everywhere
        if need >= t:
            break
        # One last pass at t' = need. The K-th best only improves as records join, so a
        # record below the current one (compared exactly, ties kept) cannot make the top
        # K. Per count c that is a largest size: c' = everywhere + c overlaps with size s
        # reach best_c / best_d iff s <= (c' * best_d - best_c * (q - c')) / best_c.
        t = max(floor, need)
        limit = np.full(top + 1, -1, dtype=np.int64)
        for c in range(t, top + 1):
            cc = everywhere + c
            if cc > 0:
                limit[c] = (cc * best_d - best_c * (q - cc)) // best_c
        cand = np.flatnonzero(counts >= t) if t > 0 else np.arange(n)
        cand = cand[size[cand] <= limit[counts[cand]]]
        cand = cand[_eligible_np(group, cand, finalised_only)]
        ci = everywhere + counts[cand].astype(np.int64)
        sim = ci / (size[cand] + q - ci)
        break
    if cand.size == 0:
        return [], []
    return _top(cand, sim, k)


__all__ = [
    "DENSE_FRACTION",
    "SMALL_GROUP",
    "Group",
    "Selection",
    "eligible",
    "prepare",
    "select_indexed",
    "select_python",
    "select_scan",
    "values",
]
