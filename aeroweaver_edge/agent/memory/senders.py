"""Per-sender caps of experience memory: how much of a peer's experience is stored
(issue 22: one compromised peer stored 8-12k records in every peer and made > 99 % of a
role's memory its own).

A peer's records are stored at most ``max_records`` rows and ``max_bytes`` bytes (state
text, invocation and tokens) per sender; beyond that, that sender's *oldest* stored records
are evicted first (nobody else's), down to 7/8 of the caps at once (so a flood at the cap
costs one recount per cap/8 records). Own records are never capped or evicted. The caller
drops evicted records from its retrieval index (``agent.memory_index``).
"""

from __future__ import annotations

import sqlite3
from typing import Final

from aeroweaver_edge.agent.memory.records import RunKey

MAX_RECORDS_PER_SENDER: Final = 4096
"""Peers' records stored per sender (oldest evicted first): about 170 episodes of 24 rounds."""
MAX_BYTES_PER_SENDER: Final = 4 * 1024 * 1024
"""Peers' stored text (state, invocation, tokens) per sender."""

_BYTES = "length(state_text) + length(invocation) + length(tokens)"


class SenderCaps:
    """Usage per peer and the eviction that keeps it within the caps."""

    def __init__(
        self, max_records: int = MAX_RECORDS_PER_SENDER, max_bytes: int = MAX_BYTES_PER_SENDER
    ) -> None:
        if max_records < 1 or max_bytes < 1:
            raise ValueError("per-sender caps must be at least 1")
        self.max_records = max_records
        self.max_bytes = max_bytes
        self.usage: dict[str, list[int]] | None = None  # origin -> [records, bytes]

    def forget(self) -> None:
        """A transaction may have rolled back: recount at the next use."""
        self.usage = None

    def of(self, db: sqlite3.Connection, origin: str) -> list[int]:
        """[records, bytes] stored of ``origin`` (peers only), counted once per open."""
        if self.usage is None:
            self.usage = {
                o: [n, b]
                for o, n, b in db.execute(
                    f"SELECT origin, count(*), coalesce(sum({_BYTES}), 0) FROM records "
                    "WHERE origin != '' GROUP BY origin"
                )
            }
        return self.usage.setdefault(origin, [0, 0])

    def make_room(
        self,
        db: sqlite3.Connection,
        origin: str,
        size: int,
        evicted: list[tuple[str, str, RunKey]],
    ) -> bool:
        """Inside the ingest transaction: evict ``origin``'s oldest records until one more
        of ``size`` bytes fits its caps. False if it can never fit (larger than the cap)."""
        cap_n, cap_b = self.max_records, self.max_bytes
        if size > cap_b:
            return False
        n, b = self.of(db, origin)
        if n + 1 <= cap_n and b + size <= cap_b:
            return True
        # Near the cap: count exactly (another process may write this file too).
        n, b = db.execute(
            f"SELECT count(*), coalesce(sum({_BYTES}), 0) FROM records WHERE origin = ?",
            (origin,),
        ).fetchone()
        gone: list[int] = []
        if n + 1 > cap_n or b + size > cap_b:
            # Down to 7/8 of the caps at once: the next cap/8 records need no recount.
            cap_n, cap_b = cap_n - max(1, cap_n // 8), cap_b - cap_b // 8
            cur = db.execute(
                f"SELECT seq, task, role, run, uav, episode, round, {_BYTES} FROM records "
                "WHERE origin = ? ORDER BY seq",
                (origin,),
            )
            for seq, task, role, run, uav, episode, rnd, nbytes in cur:
                if n + 1 <= cap_n and b + size <= cap_b:
                    break
                gone.append(seq)
                evicted.append((task, role, (run, uav, episode, rnd)))
                n, b = n - 1, b - nbytes
            cur.close()
            db.executemany("DELETE FROM records WHERE seq = ?", [(q,) for q in gone])
        usage = self.of(db, origin)
        usage[0], usage[1] = n, b
        return True


__all__ = ["MAX_BYTES_PER_SENDER", "MAX_RECORDS_PER_SENDER", "SenderCaps"]
