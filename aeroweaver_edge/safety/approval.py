"""The operator approval gate for vehicle actions (take off, land, return home).

docs/notes/safety.md (layer 7): dangerous actions need an operator token the LLM cannot
produce; hold, land and return never do. The gate sits in the daemon on two seams:

* ``offer(skill)`` when the round lists candidates: a vehicle-action skill that needs an
  approval it does not have is not callable (the LLM never sees it) and becomes *pending*,
  so an operator sees what waits for them (``aeroweaver approve``, the console, MCP);
* ``approve(uav, action)``, the flight phases' ``ApprovalPredicate``, right before the
  action runs (and, at the ``strict`` level, before the mission's launch).

Levels (``[approval] level`` in the UAV config):

| level    | take-off                                      | land, return home       |
|----------|-----------------------------------------------|-------------------------|
| normal   | one approval per mission (covers re-launches) | never need one          |
| strict   | one approval per take-off, mission launch too | one approval per action |

An approval comes from an approver identity (``[approval] approvers``; signed when the
mesh is secured), names this UAV and one action, expires ``ttl_s`` after receipt on this
UAV's monotonic clock (capped by ``max_ttl_s``), is accepted once per id, and is refused
when its own stamp says it expired in transit or when it names another mission. Every
approval is recorded (who, when, what, until when, what became of it) and published with
the pending actions (``ApprovalStatus``).
"""

from __future__ import annotations

import logging
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

import msgspec

from aeroweaver_edge.config import ApprovalConfig
from aeroweaver_edge.contracts.actions import VehicleAction
from aeroweaver_edge.contracts.wire import (
    Approval,
    ApprovalRecord,
    PendingAction,
    VehicleActionKind,
)

log = logging.getLogger(__name__)

VEHICLE_ACTION_SKILLS: Final[dict[str, VehicleActionKind]] = {
    "take_off": "takeoff",
    "land": "land",
    "return_home": "return_home",
}
"""Skill packages whose executor returns a ``VehicleAction`` of that kind."""

ACTIONS: Final[tuple[VehicleActionKind, ...]] = ("takeoff", "land", "return_home")
"""The one spelling of each vehicle action an operator approves: the wire's, the records',
the resources' and the confirm phrases' (``approve uav0 takeoff``)."""
ACTION_ALIASES: Final[dict[str, VehicleActionKind]] = {"take_off": "takeoff"}
"""Accepted on input only, for commands written before the spelling was one (the
``take_off`` skill's name); never written anywhere."""
PENDING_S: Final = 120.0  # a pending action not asked for again within this long is dropped
MAX_RECORDS: Final = 64
MAX_SEEN_IDS: Final = 4096


def parse_action(text: str) -> VehicleActionKind:
    """The canonical vehicle action (``takeoff``, ``land``, ``return_home``; ``take_off`` is
    read as ``takeoff``); ValueError naming the choices otherwise."""
    name = text.strip().lower()
    for kind in ACTIONS:
        if name == kind:
            return kind
    if name in ACTION_ALIASES:
        return ACTION_ALIASES[name]
    raise ValueError(f"unknown vehicle action {text!r}; choose takeoff, land or return_home")


def approve_phrase(uav: str, action: VehicleActionKind) -> str:
    """What an operator types to confirm an approval (console, MCP)."""
    return f"approve {uav} {action}"


def needs_approval(level: str, action: VehicleActionKind) -> bool:
    return level == "strict" or action == "takeoff"


@dataclass
class _Grant:
    record: ApprovalRecord
    deadline: float  # monotonic
    mission: str  # "" until first used at the normal level (then bound to that mission)


class ApprovalGate:
    """Approvals one UAV holds, the actions waiting for one, and the record of both."""

    def __init__(
        self,
        uav: str,
        cfg: ApprovalConfig,
        *,
        mission: Callable[[], str | None] = lambda: None,
        clock: Callable[[], float] = time.monotonic,
        wall: Callable[[], float] = time.time,
    ) -> None:
        self.uav = uav
        self.cfg = cfg
        self.mission = mission  # the mission this UAV flies now (None: none)
        self.on_change: Callable[[], None] | None = None  # status changed: publish it
        self._clock = clock
        self._wall = wall
        self._grants: list[_Grant] = []
        self._records: OrderedDict[str, ApprovalRecord] = OrderedDict()
        self._seen: OrderedDict[str, None] = OrderedDict()
        self._pending: dict[VehicleActionKind, tuple[PendingAction, float]] = {}

    @property
    def level(self) -> str:
        return self.cfg.level

    @property
    def gates_launch(self) -> bool:
        """The mission's own launch (arm + take-off) waits for an approval (strict)."""
        return self.cfg.level == "strict"

    # -- the two seams ----------------------------------------------------------------

    def offer(self, skill: str) -> bool:
        """May ``skill`` be offered to the selector this round? (Only vehicle actions can be
        withheld; a withheld one becomes pending.)"""
        kind = VEHICLE_ACTION_SKILLS.get(skill)
        if kind is None or not needs_approval(self.cfg.level, kind):
            return True
        if self._valid(kind) is not None:
            return True
        self._ask(kind, skill)
        return False

    def approve(self, uav: str, action: VehicleAction) -> bool:
        """The ``ApprovalPredicate``: may ``action`` run now? Uses up a single-use approval."""
        if uav != self.uav:
            return False
        if not needs_approval(self.cfg.level, action.kind):
            return True
        grant = self._valid(action.kind)
        if grant is None:
            self._ask(action.kind, "")
            return False
        rec = grant.record
        if self.cfg.level == "strict":
            self._grants.remove(grant)
            self._record(msgspec.structs.replace(rec, state="used", uses=rec.uses + 1))
        else:
            grant.mission = grant.mission or (self.mission() or "")
            grant.record = msgspec.structs.replace(rec, uses=rec.uses + 1,
                                                   mission_id=grant.mission)  # fmt: skip
            self._record(grant.record)
        log.info("%s: %s runs on approval %s by %s", self.uav, action.kind, rec.id, rec.by)
        self._changed()
        return True

    # -- approvals arriving ----------------------------------------------------------

    def receive(self, msg: Approval) -> ApprovalRecord:
        """Check and record an approval (the mesh already checked its signature when
        secured); returns its record, ``state="refused"`` with the reason if refused."""
        now_wall = self._wall()
        ttl = min(msg.ttl_s, self.cfg.max_ttl_s)
        rec = ApprovalRecord(
            id=msg.id, action=msg.action, sender=msg.h.sender, by=msg.by or msg.h.sender,
            issued=msg.h.stamp, received=now_wall, expires=now_wall + ttl,
            mission_id=msg.mission_id,
        )  # fmt: skip
        why = self._refusal(msg, now_wall)
        if why is not None:
            rec = msgspec.structs.replace(rec, state="refused", reason=why)
            if why != "duplicate approval id":  # a duplicate keeps the original's record
                self._record(rec)
            log.warning("%s: approval %s from %s refused: %s", self.uav, msg.id, msg.h.sender, why)
            return rec
        self._seen[msg.id] = None
        while len(self._seen) > MAX_SEEN_IDS:
            self._seen.popitem(last=False)
        self._grants.append(_Grant(rec, self._clock() + ttl, msg.mission_id))
        self._pending.pop(msg.action, None)
        self._record(rec)
        log.info(
            "%s: %s approved by %s (%s) for %.0f s",
            self.uav, msg.action, rec.by, rec.sender, ttl,
        )  # fmt: skip
        self._changed()
        return rec

    def _refusal(self, msg: Approval, now_wall: float) -> str | None:
        if msg.uav != self.uav:
            return f"addressed to {msg.uav}"
        if msg.h.sender not in self.cfg.approvers:
            return f"{msg.h.sender!r} is not an approver"
        if msg.id in self._seen or msg.id in self._records:
            return "duplicate approval id"
        if msg.h.stamp + msg.ttl_s < now_wall:
            return "expired before it arrived"
        current = self.mission()
        if msg.mission_id and current is not None and msg.mission_id != current:
            return f"for mission {msg.mission_id}, flying {current}"
        return None

    # -- status -----------------------------------------------------------------------

    def pending(self) -> list[PendingAction]:
        now = self._clock()
        for kind, (_p, last) in list(self._pending.items()):
            if now - last > PENDING_S:
                del self._pending[kind]
        return [p for p, _last in self._pending.values()]

    def records(self) -> list[ApprovalRecord]:
        self._expire()
        return list(self._records.values())

    def _valid(self, kind: VehicleActionKind) -> _Grant | None:
        self._expire()
        current = self.mission() or ""
        for grant in self._grants:
            if grant.record.action != kind:
                continue
            if grant.mission and current and grant.mission != current:
                continue  # approved for another mission
            return grant
        return None

    def _expire(self) -> None:
        now = self._clock()
        live = [g for g in self._grants if g.deadline > now]
        if len(live) != len(self._grants):
            for g in self._grants:
                if g.deadline <= now:
                    self._record(msgspec.structs.replace(g.record, state="expired"))
            self._grants = live
            self._changed()

    def _ask(self, kind: VehicleActionKind, skill: str) -> None:
        now = self._clock()
        known = self._pending.get(kind)
        if known is None:
            self._pending[kind] = (PendingAction(action=kind, since=self._wall(), skill=skill), now)
            log.info("%s: %s waits for an operator approval", self.uav, kind)
            self._changed()
        else:
            self._pending[kind] = (known[0], now)

    def _record(self, rec: ApprovalRecord) -> None:
        self._records[rec.id] = rec
        self._records.move_to_end(rec.id)
        while len(self._records) > MAX_RECORDS:
            self._records.popitem(last=False)

    def _changed(self) -> None:
        if self.on_change is not None:
            self.on_change()


__all__ = [
    "ACTIONS",
    "ACTION_ALIASES",
    "VEHICLE_ACTION_SKILLS",
    "ApprovalGate",
    "approve_phrase",
    "needs_approval",
    "parse_action",
]
