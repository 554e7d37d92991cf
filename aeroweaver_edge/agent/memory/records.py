"""What experience memory stores and hands out: records, neighbours, keys (agent.memory).

Kept apart from the SQLite plumbing and the retrieval index so that readers of a record
(publishing, inspection tools, tests) need neither.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final

from aeroweaver_edge.contracts.wire import MAX_TEXT, ExperienceRecord, Header

LOCAL: Final = ""  # ``origin`` of records appended by this memory's own daemon

Key = tuple[str, int, int]  # (uav, episode, round) within one run
RunKey = tuple[str, str, int, int]  # (run, uav, episode, round): unique in a file

COLUMNS: Final = (
    "seq, task, role, uav, episode, round, state_text, skill, invocation, reward, ret, final, "
    "origin, reward_source, run"
)
"""The ``records`` columns ``stored`` reads, in its order."""


@dataclass(frozen=True, slots=True)
class StoredRecord:
    """One stored decision with its provenance."""

    seq: int
    task: str
    role: str
    uav: str
    episode: int
    round: int
    state_text: str
    skill: str
    invocation: str
    reward: float | None
    ret: float | None
    final: bool
    origin: str  # "" = appended by this daemon, else the peer that published it
    reward_source: str
    run: str = ""

    def to_wire(self, h: Header) -> ExperienceRecord:
        """The payload a daemon publishes on ``.../experience`` (it supplies the header)."""
        return ExperienceRecord(
            h=h,
            task=self.task,
            role=self.role,
            uav=self.uav,
            episode=self.episode,
            round=self.round,
            state_text=self.state_text,
            skill=self.skill,
            invocation=self.invocation,
            reward=self.reward,
            ret=self.ret,
            final=self.final,
            reward_source=self.reward_source,
            run=self.run,
        )


@dataclass(frozen=True, slots=True)
class Neighbour:
    """One member of a retrieved neighbourhood (for inspection, tests and reports)."""

    key: Key
    skill: str
    ret: float
    similarity: float
    seq: int
    run: str = ""


def skill_of(name: str) -> str:
    """``cover_landmark(target=L2)`` -> ``cover_landmark``: a parameterisation shares its
    skill's advantage, so callers may pass invocations as well as skill names."""
    return name.split("(", 1)[0].strip()


def stored(row: tuple[Any, ...]) -> StoredRecord:
    """A ``StoredRecord`` from a row of ``SELECT {COLUMNS}``."""
    seq, task, role, uav, episode, rnd, text, skill, inv, reward, ret, final, origin, src, run = row
    return StoredRecord(
        seq,
        task,
        role,
        uav,
        episode,
        rnd,
        text,
        skill,
        inv,
        reward,
        ret,
        bool(final),
        origin,
        src,
        run,
    )


def invalid(record: ExperienceRecord) -> str | None:
    """Why a peer's record must not enter memory (memory poisoning is a threat model item)."""
    for name in ("reward", "ret"):
        value = getattr(record, name)
        if value is not None and not math.isfinite(value):
            return f"non-finite {name}"
    if len(record.state_text) > MAX_TEXT or len(record.invocation) > MAX_TEXT:
        return "oversize text"
    if not (record.task and record.role and record.uav and record.skill):
        return "empty task, role, uav or skill"
    return None


__all__ = [
    "COLUMNS",
    "LOCAL",
    "Key",
    "Neighbour",
    "RunKey",
    "StoredRecord",
    "invalid",
    "skill_of",
    "stored",
]
