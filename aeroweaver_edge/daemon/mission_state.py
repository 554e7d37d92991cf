"""The daemon's latest mission context and assignment, kept current from the Commander.

Authority comes from the live Commander, not from a payload's key or epoch:

- only payloads whose header names the Commander identity count;
- with signatures (``authenticated=True``) the epoch is authentic: a newer one is a
  restarted Commander and replaces the old session; older ones are refused for good;
- without signatures a payload's epoch could be forged (2^62 would outrank every genuine
  one), so with ``track_commander`` the first epoch seen after the Commander's liveliness
  token appears fixes the session and any other epoch is refused while it lasts;
- with ``track_commander`` authority ends with the Commander's liveliness: context and
  assignment are dropped (the UAV holds) and the next token starts a fresh session; the
  daemon should then query the context and its assignment (the Commander serves both), as
  it does at start-up, since a payload that raced ahead of the token is not kept.

Without ``track_commander`` (a daemon that does not watch the Commander's token) a newer
epoch always wins, as before; that mode is only safe with signatures.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from aeroweaver_edge.contracts.observation import MissionView
from aeroweaver_edge.contracts.wire import Assignment, Header, MissionContext

COMMANDER = "cmdr"


@dataclass
class MissionState:
    uav: str
    context: MissionContext | None = None
    assignment: Assignment | None = None
    changes: int = 0  # how often the view changed: a new view means a rebuilt prompt context
    commander: str = COMMANDER
    track_commander: bool = False  # authority needs the Commander's live token
    rejected: Counter[str] = field(default_factory=Counter)
    _alive: bool = False
    _epoch: int | None = None  # epoch of the current Commander session
    _floor: int = -1  # highest authenticated Commander epoch: older sessions stay out
    # Payloads that came before the first Commander token did (links come up in any order).
    # Between sessions nothing is kept: a late payload of the old session must not fix the
    # epoch of the next one (a restarted Commander is caught up by a query instead).
    _early: list[tuple[MissionContext | Assignment, bool]] = field(default_factory=list)
    _ever_alive: bool = False
    _last_state: str = ""  # state of the last context taken; kept when the session ends

    def update_context(self, ctx: MissionContext, *, authenticated: bool = False) -> None:
        """Take ``ctx`` if it is admitted and newer; a refusal is counted in ``rejected``."""
        if self._admit(ctx, authenticated) is None:
            cur = self.context
            if cur is None or (ctx.h.epoch, ctx.h.seq) > (cur.h.epoch, cur.h.seq):
                self.context = ctx
                self._last_state = ctx.state
                self.changes += 1

    def update_assignment(self, a: Assignment, *, authenticated: bool = False) -> None:
        """Take ``a`` if it is for this UAV, admitted and newer (by revision, then seq)."""
        if a.uav != self.uav or self._admit(a, authenticated) is not None:
            return
        cur = self.assignment
        if cur is None or (a.h.epoch, a.revision, a.h.seq) > (cur.h.epoch, cur.revision, cur.h.seq):
            self.assignment = a
            self.changes += 1

    @property
    def commander_is_alive(self) -> bool:
        """The Commander's token is up (as last told by ``commander_alive``)."""
        return self._alive

    @property
    def commander_lost(self) -> bool:
        """The tracked Commander's session went away in the middle of an active mission
        (not after it ended the mission): a flying UAV holds and waits for it to come back
        (docs/notes/safety.md, "Commander loss"), it does not treat that as the mission's end."""
        return (
            self.track_commander
            and self._ever_alive
            and not self._alive
            and self._last_state == "active"
        )

    def commander_alive(self, alive: bool) -> None:
        """The Commander's liveliness token appeared (True) or went away (False)."""
        if alive == self._alive:
            return
        self._alive = alive
        self._epoch = None  # a token is one session; the next one may start afresh
        if not alive:
            self._drop()
            return
        self._ever_alive = True
        early, self._early = self._early, []
        for msg, authenticated in early:
            if isinstance(msg, MissionContext):
                self.update_context(msg, authenticated=authenticated)
            else:
                self.update_assignment(msg, authenticated=authenticated)

    def _admit(self, msg: MissionContext | Assignment, authenticated: bool) -> str | None:
        h: Header = msg.h
        why = self._check(h, authenticated)
        if why == "no_live_commander" and not self._ever_alive:
            self._early = [*self._early[-7:], (msg, authenticated)]  # bounded
        if why is not None:
            self.rejected[why] += 1
            return why
        if self._epoch is not None and h.epoch != self._epoch:
            self._drop()  # a restarted Commander: nothing of its old session carries over
        self._epoch = h.epoch
        if authenticated:
            self._floor = max(self._floor, h.epoch)
        return None

    def _check(self, h: Header, authenticated: bool) -> str | None:
        if h.sender != self.commander:
            return "not_commander"
        if self.track_commander and not self._alive:
            return "no_live_commander"
        if authenticated and h.epoch < self._floor:
            return "old_epoch"
        if self._epoch is None or h.epoch == self._epoch:
            return None
        if h.epoch < self._epoch:
            return "old_epoch"
        if not authenticated and self.track_commander:
            return "epoch_contested"
        return None

    def _drop(self) -> None:
        if self.context is not None or self.assignment is not None:
            self.context = self.assignment = None
            self.changes += 1

    def view(self) -> MissionView | None:
        """The current view, or ``None`` until both context and a matching assignment exist."""
        c, a = self.context, self.assignment
        if c is None or a is None or a.mission_id != c.mission_id or c.state != "active":
            return None
        return MissionView(
            mission_id=c.mission_id,
            task=c.task,
            text=c.text,
            role=a.role,
            local_goal=a.local_goal,
            skills=tuple(a.skills),
            constraints=tuple(c.constraints),
        )
