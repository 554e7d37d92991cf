"""What an operator may do over the mesh, and nothing more: stop the mission (through the
Commander) and approve a vehicle action (for one UAV, which checks it itself).

Used by ``aeroweaver approve``, the console and the MCP server. It writes only operator
keys (``aw/<swarm>/operator/**``; the ``operator`` role's grants when the mesh is secured,
and its payloads are signed by the operator identity), never a UAV's or the Commander's.
Each action waits for its effect to be seen: the Commander's ended context, the UAV's
acknowledgement. Before writing it waits for the receiver's liveliness token, which is
declared after the receiver's subscribers, so the write cannot outrun them.
"""

from __future__ import annotations

import asyncio
import contextlib
import getpass
import uuid
from dataclasses import dataclass
from typing import TYPE_CHECKING

from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.contracts.wire import (
    Approval,
    ApprovalRecord,
    ApprovalStatus,
    HeaderFactory,
    Keys,
    MissionContext,
    OperatorCommand,
    VehicleActionKind,
)

if TYPE_CHECKING:
    from aeroweaver_edge.mesh.session import Mesh

OPERATOR = "operator"


class OperatorError(UserError):
    """An operator action could not be carried out (nobody answered, or it was refused)."""


@dataclass(frozen=True)
class StopPlan:
    """What a stop will do, said before it is done (console, MCP)."""

    mission_id: str
    task: str
    participants: tuple[str, ...]

    def describe(self) -> str:
        uavs = ", ".join(self.participants) or "no UAV"
        return (
            f"publish an operator stop for mission {self.mission_id} ({self.task}) to the "
            f"Commander; it ends the mission and {uavs} hold, then land or return home as "
            "each is configured (vehicle.end_action). Nothing is sent to a vehicle."
        )


def default_person() -> str:
    """Who the records name when the caller does not say (the login name)."""
    try:
        return getpass.getuser()[:64]
    except Exception:  # no login name (a container): the identity alone is recorded
        return ""


class OperatorLink:
    """An operator's actions on one swarm, over an open mesh session."""

    def __init__(
        self, mesh: Mesh, swarm: str, *, identity: str = OPERATOR, person: str | None = None
    ) -> None:
        self.mesh = mesh
        self.keys = Keys(swarm)
        # When secured, the mesh signs as its identity: the header must name the same one.
        sec = mesh.security
        name = sec.config.identity if sec is not None else identity
        self.headers = HeaderFactory(name)
        self.person = default_person() if person is None else person[:64]

    # -- reading ----------------------------------------------------------------------

    async def context(self, timeout_s: float = 1.5) -> MissionContext | None:
        """The Commander's current mission context (None: no Commander answered)."""
        got = await self.mesh.get(self.keys.context, MissionContext, timeout_s=timeout_s)
        ctxs = [m for _k, m in got if m.h.sender == "cmdr"]
        return max(ctxs, key=lambda c: (c.h.epoch, c.h.seq)) if ctxs else None

    async def approval_status(self, uav: str, timeout_s: float = 1.5) -> ApprovalStatus | None:
        got = await self.mesh.get(self.keys.approval_status(uav), ApprovalStatus, timeout_s)
        mine = [m for _k, m in got if m.uav == uav == m.h.sender]
        return mine[-1] if mine else None

    async def _wait_token(self, key: str, what: str, timeout_s: float) -> None:
        watch = self.mesh.watch_liveliness(key)
        try:
            async with asyncio.timeout(timeout_s):
                async for _key, alive in watch:
                    if alive:
                        return
        except TimeoutError:
            raise OperatorError(f"{what} is not on the mesh (waited {timeout_s:g} s)") from None
        finally:
            await watch.aclose()

    # -- stopping the mission -----------------------------------------------------------

    async def plan_stop(self, timeout_s: float = 3.0) -> StopPlan:
        await self._wait_token(self.keys.alive_cmdr, "the Commander", timeout_s)
        ctx = await self.context()
        if ctx is None:
            raise OperatorError("the Commander has no mission to stop")
        if ctx.state == "ended":
            raise OperatorError(f"mission {ctx.mission_id} has already ended")
        return StopPlan(ctx.mission_id, ctx.task, tuple(ctx.participants))

    async def stop(self, plan: StopPlan, reason: str = "", timeout_s: float = 5.0) -> str:
        """Ask the Commander to end ``plan``'s mission; returns the Commander's end note
        once its ended context is seen."""
        sub = self.mesh.subscribe(self.keys.context, MissionContext, maxsize=16)
        try:
            await self._wait_token(self.keys.alive_cmdr, "the Commander", timeout_s)
            self.mesh.put(
                self.keys.operator_command,
                OperatorCommand(h=self.headers.next(), action="stop", mission_id=plan.mission_id,
                                reason=reason[:200], by=self.person),
                block=True,
            )  # fmt: skip
            async with asyncio.timeout(timeout_s):
                async for _key, ctx in sub:
                    if ctx.mission_id == plan.mission_id and ctx.state == "ended":
                        return ctx.constraints[-1] if ctx.constraints else "ended"
        except TimeoutError:
            pass
        finally:
            await sub.aclose()
        last = await self.context()  # the ended context may have raced our subscription
        if last is not None and last.mission_id == plan.mission_id and last.state == "ended":
            return last.constraints[-1] if last.constraints else "ended"
        raise OperatorError(
            f"the Commander did not end mission {plan.mission_id} within {timeout_s:g} s "
            "(is this identity one of its operators?)"
        )

    # -- approving a vehicle action -----------------------------------------------------

    async def approve(
        self,
        uav: str,
        action: VehicleActionKind,
        ttl_s: float,
        *,
        mission_id: str = "",
        timeout_s: float = 5.0,
    ) -> ApprovalRecord:
        """Send an approval to ``uav`` and return its record as the UAV acknowledged it;
        OperatorError when it was refused or not acknowledged in time."""
        approval_id = uuid.uuid4().hex
        sub = self.mesh.subscribe(self.keys.approval_status(uav), ApprovalStatus, maxsize=64)
        record: ApprovalRecord | None = None
        try:
            await self._wait_token(self.keys.alive_uav(uav), uav, timeout_s)
            self.mesh.put(
                self.keys.approval(uav),
                Approval(h=self.headers.next(), id=approval_id, uav=uav, action=action,
                         ttl_s=ttl_s, by=self.person, mission_id=mission_id),
                block=True,
            )  # fmt: skip
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(timeout_s):
                    async for _key, st in sub:
                        if st.uav == uav == st.h.sender and st.ack == approval_id:
                            record = _record_of(st, approval_id)
                            break
        finally:
            await sub.aclose()
        if record is None:  # the acknowledgement may have raced our subscription
            status = await self.approval_status(uav)
            record = _record_of(status, approval_id) if status is not None else None
        if record is None:
            raise OperatorError(f"{uav} did not acknowledge the approval within {timeout_s:g} s")
        if record.state == "refused":
            raise OperatorError(f"{uav} refused the approval: {record.reason}")
        return record


def _record_of(status: ApprovalStatus, approval_id: str) -> ApprovalRecord | None:
    return next((r for r in status.records if r.id == approval_id), None)


def record_dict(rec: ApprovalRecord) -> dict[str, object]:
    """A record for JSON output (console, MCP, CLI)."""
    return {
        "id": rec.id, "action": rec.action, "state": rec.state, "by": rec.by,
        "sender": rec.sender, "issued": rec.issued, "received": rec.received,
        "expires": rec.expires, "mission_id": rec.mission_id, "uses": rec.uses,
        "reason": rec.reason,
    }  # fmt: skip


__all__ = ["OPERATOR", "OperatorError", "OperatorLink", "StopPlan", "record_dict"]
