"""Frames: one JSON object per world round, the one shape the console page draws.

A frame is a trace round row (docs/traces.md) plus what the page needs to draw it alone:

    {"i": index, "episode", "round", "stamp" (world publish time, s; null in a replay),
     "uavs": [the UAVs we fly], "bodies": [{id, kind, pos, vel, role}], "entities": [...],
     "held": [...], "messages": [{from, to, seq}], "missed", "absent", "rewards": {id: r},
     "team_reward": mean reward of our UAVs this round, "complete", "done", "reason",
     "decisions": {uav: trace decision (skill, invocation, held, hold_cause, tokens,
                   options, base, advantage, chosen, reason, ...)}}

Live frames come from the world's ``WorldSnapshot`` joined with the UAVs' progress reports
(a report that arrives after its round's frame becomes a *patch*); replay frames come from
a trace file. ``FrameStore`` keeps them (bounded) and wakes every event stream on change.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
from collections import OrderedDict
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from aeroweaver_edge.contracts.wire import ProgressReport, WorldSnapshot
from aeroweaver_edge.orchestration.trace import decision_dict, entity_dict
from aeroweaver_edge.runtime.json_out import json_safe

MAX_FRAMES = 5000
MAX_PATCHES = 20_000
MAX_EARLY_ROUNDS = 64  # rounds whose reports came before their snapshot


def _finite(x: float) -> float | None:
    return round(x, 6) if math.isfinite(x) else None


def team_reward(rewards: Mapping[str, float | None], ours: Iterable[str]) -> float | None:
    vals = [rewards.get(u) for u in ours]
    good = [v for v in vals if v is not None and math.isfinite(v)]
    return round(math.fsum(good) / len(good), 6) if good and len(good) == len(vals) else None


def snapshot_frame(snap: WorldSnapshot) -> dict[str, Any]:
    rewards = {u: _finite(r) for u, r in sorted(snap.rewards.items())}
    return {
        "episode": snap.episode,
        "round": snap.round,
        "stamp": snap.h.stamp,
        "task": snap.task,
        "uavs": list(snap.uavs),
        "bodies": [entity_dict(b) for b in snap.bodies],
        "entities": [entity_dict(e) for e in snap.entities],
        "held": list(snap.held),
        "messages": [{"from": m.sender, "to": m.to, "seq": m.seq} for m in snap.messages],
        "guesses": dict(snap.guesses),
        "missed": list(snap.missed),
        "absent": list(snap.absent),
        "rewards": rewards,
        "team_reward": team_reward(rewards, snap.uavs),
        "complete": snap.complete,
        "done": snap.done,
        "reason": snap.reason,
        "decisions": {},
    }


def report_decision(rep: ProgressReport) -> dict[str, Any]:
    return {**decision_dict(rep), "role": rep.role}


def trace_frame(row: Mapping[str, Any], ours: list[str]) -> dict[str, Any]:
    """A frame from a trace's round row (``ours``: the header's roles, the UAVs we fly)."""
    commands: Mapping[str, Any] = row.get("commands") or {}
    uavs = sorted(commands) or ours
    rewards = dict(row.get("rewards") or {})
    return {
        "episode": row["episode"],
        "round": row["round"],
        "stamp": None,
        "uavs": uavs,
        "bodies": list(row.get("bodies") or []),
        "entities": list(row.get("entities") or []),
        "held": [u for u in uavs if (c := commands.get(u)) is None or c.get("held")],
        "messages": list(row.get("messages") or []),
        "guesses": {u: c["guess"] for u, c in commands.items() if c.get("guess") is not None},
        "missed": list(row.get("missed") or []),
        "absent": list(row.get("absent") or []),
        "rewards": rewards,
        "team_reward": team_reward(rewards, uavs),
        "complete": bool(row.get("complete")),
        "done": bool(row.get("done")),
        "reason": row.get("reason") or "",
        "decisions": dict(row.get("decisions") or {}),
    }


class TraceError(ValueError):
    """A trace file that cannot be replayed; the message names the file and line."""


def load_trace(path: Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """(header, frames) of a trace file (docs/traces.md)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise TraceError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise TraceError(f"{path}: not UTF-8 text (is it a trace from --trace?)") from None
    header: dict[str, Any] | None = None
    frames: list[dict[str, Any]] = []
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as exc:
            raise TraceError(f"{path}:{n}: not JSON ({exc.msg})") from None
        if not isinstance(row, dict):
            raise TraceError(f"{path}:{n}: not a JSON object")
        kind = row.get("type")
        if header is None:
            if kind != "run":
                raise TraceError(f'{path}:{n}: the first line must be the {{"type": "run"}} header')
            header = row
        elif kind == "round":
            try:
                frame = trace_frame(row, sorted(header.get("roles") or {}))
            except (KeyError, TypeError, AttributeError) as exc:
                raise TraceError(f"{path}:{n}: malformed round ({exc})") from None
            frame["i"] = len(frames)
            frames.append(frame)
    if header is None:
        raise TraceError(f"{path}: empty (no trace header)")
    if not frames:
        raise TraceError(f"{path}: no rounds to replay")
    return header, frames


class FrameStore:
    """Frames, decision patches, mission meta and approval status, with change wake-ups.

    Everything runs on the event loop; ``wait_change`` wakes every waiting stream once per
    change (they coalesce: a slow stream sends only the newest frame).
    """

    def __init__(self, max_frames: int = MAX_FRAMES) -> None:
        self.max_frames = max_frames
        self.frames: list[dict[str, Any]] = []
        self.first = 0  # index of frames[0] (older frames were dropped)
        self._where: dict[tuple[int, int], int] = {}
        self._early: OrderedDict[tuple[int, int], dict[str, dict[str, Any]]] = OrderedDict()
        self.patches: list[tuple[int, int, str, dict[str, Any]]] = []  # (seq, i, uav, decision)
        self.patch_seq = 0
        self.meta: dict[str, Any] = {}
        self.meta_version = 0
        self.approvals: dict[str, dict[str, Any]] = {}
        self.approvals_version = 0
        self.closed = False
        self._wake = asyncio.Event()

    # -- change notification ----------------------------------------------------------

    def _changed(self) -> None:
        self._wake.set()
        self._wake = asyncio.Event()

    async def wait_change(self, timeout_s: float) -> None:
        event = self._wake
        if self.closed:
            return
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                await event.wait()

    async def wait_frame(self, timeout_s: float, after: int) -> None:
        """Wait up to ``timeout_s`` unless a frame newer than ``after`` arrives first."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while self.last_index <= after and not self.closed:
            left = deadline - loop.time()
            if left <= 0:
                return
            await self.wait_change(left)

    def close(self) -> None:
        """The console is going away: every stream sends ``ended`` once more and stops."""
        if not self.meta.get("ended"):
            self.meta = {**self.meta, "ended": True}
            self.meta_version += 1
        self.closed = True
        self._changed()

    # -- frames -----------------------------------------------------------------------

    @property
    def last_index(self) -> int:
        return self.first + len(self.frames) - 1

    def frame(self, i: int) -> dict[str, Any] | None:
        j = i - self.first
        return self.frames[j] if 0 <= j < len(self.frames) else None

    def since(self, start: int) -> list[dict[str, Any]]:
        return self.frames[max(0, start - self.first) :]

    def add_frame(self, frame: dict[str, Any]) -> int:
        # A field frame (``field.py``) is a sample, not a world round: it carries its own
        # decisions and takes no patches, so it never enters the (episode, round) index.
        sample = frame.get("source") == "field"
        key = (frame["episode"], frame["round"])
        if not sample and key in self._where:  # a duplicate snapshot: keep the first
            return self._where[key]
        frame["i"] = i = self.first + len(self.frames)
        if not sample:
            frame["decisions"] = {**self._early.pop(key, {}), **frame.get("decisions", {})}
            self._where[key] = i
        self.frames.append(frame)
        if len(self.frames) > self.max_frames:
            old = self.frames.pop(0)
            if old.get("source") != "field":
                self._where.pop((old["episode"], old["round"]), None)
            self.first += 1
        self._changed()
        return i

    def add_decision(self, episode: int, rnd: int, uav: str, decision: dict[str, Any]) -> None:
        i = self._where.get((episode, rnd))
        if i is None:  # its round's snapshot has not come yet
            self._early.setdefault((episode, rnd), {})[uav] = decision
            while len(self._early) > MAX_EARLY_ROUNDS:
                self._early.popitem(last=False)
            return
        frame = self.frame(i)
        if frame is None:
            return
        frame["decisions"][uav] = decision
        self.patch_seq += 1
        self.patches.append((self.patch_seq, i, uav, decision))
        if len(self.patches) > MAX_PATCHES:
            del self.patches[: len(self.patches) - MAX_PATCHES]
        self._changed()

    def patches_since(self, seq: int) -> dict[int, dict[str, dict[str, Any]]]:
        """Decisions patched after ``seq``, by frame index."""
        out: dict[int, dict[str, dict[str, Any]]] = {}
        for s, i, uav, d in reversed(self.patches):
            if s <= seq:
                break
            out.setdefault(i, {}).setdefault(uav, d)
        return out

    # -- mission meta and approvals -----------------------------------------------------

    def update_meta(self, **fields: Any) -> None:
        merged = {**self.meta, **fields}
        if merged != self.meta:
            self.meta = merged
            self.meta_version += 1
            self._changed()

    def set_approvals(self, uav: str, status: dict[str, Any]) -> None:
        if self.approvals.get(uav) != status:
            self.approvals[uav] = status
            self.approvals_version += 1
            self._changed()


def encode(value: Any) -> str:
    """Compact strict JSON (non-finite floats as null)."""
    return json.dumps(json_safe(value), separators=(",", ":"), allow_nan=False)


__all__ = [
    "FrameStore",
    "TraceError",
    "encode",
    "load_trace",
    "report_decision",
    "snapshot_frame",
    "team_reward",
    "trace_frame",
]
