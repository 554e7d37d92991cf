"""The Commander: supplies mission context and per-UAV assignments, watches progress.

It has no flight authority: it writes only under ``aw/<swarm>/cmdr/...`` and never under a
UAV's keys. Context and assignments are also served by queryables so a daemon that starts
late or restarts catches up. An operator (``aeroweaver console``, ``aeroweaver mcp``) stops
the mission through it (``aw/<swarm>/operator/command``): the Commander publishes the ended
context and every UAV holds, then lands or returns by itself.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
from collections.abc import Callable
from typing import TYPE_CHECKING

from aeroweaver_edge.contracts.wire import (
    Assignment,
    HeaderFactory,
    Keys,
    MissionContext,
    OperatorCommand,
    ProgressReport,
)
from aeroweaver_edge.runtime.lifecycle import cancel_all
from commander.activation import HOLD
from commander.plan import MissionPlan, UavAssignment
from commander.progress import ProgressBoard

if TYPE_CHECKING:
    from aeroweaver_edge.mesh.session import Mesh, Subscription


OPERATOR = "operator"
"""The operator identity's name (``security.identity.OPERATOR``)."""


class Commander:
    def __init__(
        self,
        mesh: Mesh,
        swarm: str,
        headers: HeaderFactory | None = None,
        operators: frozenset[str] = frozenset({OPERATOR}),
    ) -> None:
        self.mesh = mesh
        self.keys = Keys(swarm)
        self.headers = headers or HeaderFactory("cmdr")
        self.plan: MissionPlan | None = None
        self.board = ProgressBoard(mission_id="")
        self._context: MissionContext | None = None
        self._assignments: dict[str, Assignment] = {}
        self._revision = 0
        self._tasks: list[asyncio.Task[None]] = []
        self._queryables: set[str] = set()
        self.report_event = asyncio.Event()
        # Read-only listeners of every accepted report (traces, the console): called on the
        # loop, after the board took the report; they must not block.
        self.report_listeners: list[Callable[[ProgressReport], None]] = []
        # Operator stops: accepted only from these identities (signed ones when secured),
        # for the current mission, once per (sender, epoch, seq).
        self.operators = operators
        self.ended = asyncio.Event()  # set when the mission ends (operator stop or the run)
        self.end_reason = ""
        self.operator_log: list[dict[str, object]] = []  # every operator command, accepted or not
        self._operator_seen: set[tuple[str, int, int]] = set()

    async def start(self) -> None:
        # Declare everything before the liveliness token: a peer that sees the token may
        # report at once, and that report must find our subscriber.
        reports = self.mesh.subscribe(self.keys.report("*"), ProgressReport)
        commands = self.mesh.subscribe(self.keys.operator_command, OperatorCommand, maxsize=16)
        self.mesh.declare_queryable(self.keys.context, lambda: self._context)
        self._tasks.append(asyncio.create_task(self._pump_reports(reports), name="cmdr-reports"))
        self._tasks.append(asyncio.create_task(self._pump_operator(commands), name="cmdr-operator"))
        self.mesh.declare_token(self.keys.alive_cmdr)

    async def aclose(self) -> None:
        await cancel_all(self._tasks)

    async def _pump_reports(self, reports: Subscription[ProgressReport]) -> None:
        async for key, rep in reports:
            if key != self.keys.report(rep.uav):
                self.board.foreign += 1  # a UAV reports only on its own key
                continue
            if self.board.add(rep):
                for listener in self.report_listeners:
                    listener(rep)
            self.report_event.set()

    async def _pump_operator(self, commands: Subscription[OperatorCommand]) -> None:
        async for _key, cmd in commands:
            verdict = self.take_operator_command(cmd)
            self.operator_log.append(
                {"sender": cmd.h.sender, "by": cmd.by, "action": cmd.action,
                 "mission_id": cmd.mission_id, "reason": cmd.reason, "verdict": verdict}
            )  # fmt: skip
            del self.operator_log[:-64]

    def take_operator_command(self, cmd: OperatorCommand) -> str:
        """Act on an operator command; returns ``"stopped"`` or why it was refused."""
        if cmd.h.sender not in self.operators:
            return "not an operator"
        ctx = self._context
        if ctx is None or cmd.mission_id != ctx.mission_id:
            return "not the current mission"
        seen = (cmd.h.sender, cmd.h.epoch, cmd.h.seq)
        if seen in self._operator_seen:
            return "replayed"
        self._operator_seen.add(seen)  # bounded: one mission ends once
        if ctx.state == "ended":
            return "already ended"
        who = cmd.by or cmd.h.sender
        self.end_mission(f"operator stop by {who}" + (f": {cmd.reason}" if cmd.reason else ""))
        return "stopped"

    async def wait_ready(self, uavs: list[str], timeout_s: float) -> set[str]:
        """Wait until every UAV acknowledged its assignment; returns the ones that did not."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                while not set(uavs) <= set(self.board.ready):
                    self.report_event.clear()
                    await self.report_event.wait()
        return set(uavs) - set(self.board.ready)

    def end_mission(self, reason: str = "operator stop") -> None:
        """Publish the ended state: every daemon drops its assignment and holds."""
        if self._context is None:
            return
        c = self._context
        self.end_reason = self.end_reason or reason
        self.ended.set()
        self._context = MissionContext(
            h=self.headers.next(), mission_id=c.mission_id, task=c.task, text=c.text,
            constraints=[*c.constraints, f"ended: {reason}"], participants=c.participants,
            episode=c.episode, state="ended",
        )  # fmt: skip
        self.mesh.put(self.keys.context, self._context, block=True)

    def publish(self, plan: MissionPlan, episode: int = 0) -> None:
        """Publish (or republish after a change) the context and every assignment."""
        self.plan = plan
        self._revision += 1
        self.ended.clear()
        self.end_reason = ""
        if self.board.mission_id != plan.mission_id:
            self.board = ProgressBoard(plan.mission_id)
        self._context = MissionContext(
            h=self.headers.next(),
            mission_id=plan.mission_id,
            task=plan.task,
            text=plan.text,
            constraints=list(plan.constraints),
            participants=plan.participants,
            episode=episode,
        )
        self.mesh.put(self.keys.context, self._context, block=True)
        # A UAV left out of this plan is told to hold, and catches up on that, not on its
        # old assignment.
        released = {
            u: UavAssignment("unassigned", "Hold position: not part of this mission.", (HOLD,))
            for u in set(self._assignments) - set(plan.assignments)
        }
        for uav, a in sorted({**released, **plan.assignments}.items()):
            key = self.keys.assign(uav)
            msg = Assignment(
                h=self.headers.next(),
                mission_id=plan.mission_id,
                uav=uav,
                role=a.role,
                local_goal=a.local_goal,
                skills=list(a.skills),
                revision=self._revision,
            )
            self._assignments[uav] = msg
            if key not in self._queryables:
                self._queryables.add(key)
                self.mesh.declare_queryable(key, functools.partial(self._assignments.get, uav))
            self.mesh.put(key, msg, block=True)
