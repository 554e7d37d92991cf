"""The daemon's latest mission context and assignment, kept current from the Commander."""

from __future__ import annotations

from dataclasses import dataclass

from aeroweaver_edge.observation import MissionView
from aeroweaver_edge.wire import Assignment, MissionContext


@dataclass
class MissionState:
    uav: str
    context: MissionContext | None = None
    assignment: Assignment | None = None
    changes: int = 0  # how often the view changed: a new view means a rebuilt prompt context

    def update_context(self, ctx: MissionContext) -> None:
        if self.context is None or (ctx.h.epoch, ctx.h.seq) > (
            self.context.h.epoch,
            self.context.h.seq,
        ):
            self.context = ctx
            self.changes += 1

    def update_assignment(self, a: Assignment) -> None:
        if a.uav != self.uav:
            return
        cur = self.assignment
        if cur is None or (a.h.epoch, a.revision, a.h.seq) > (cur.h.epoch, cur.revision, cur.h.seq):
            self.assignment = a
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
