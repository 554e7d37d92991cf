"""The console's read-only view of a swarm: it subscribes, it never puts.

One Zenoh session (``MeshConfig``; with ``[mesh.security]`` the ``observer`` identity, or the
``operator`` identity when the console may act) follows:

* ``sim/snapshot``: the world after each round (one frame per round);
* ``uav/*/report``: each UAV's decision (options, scores, pick, hold and its cause);
* ``cmdr/context`` and ``cmdr/assign/*``: the mission, roles, goals, active skills;
* ``uav/*/approval``: vehicle actions waiting for an operator, and the approval records;
* ``alive/**``: who is up.

With no simulated world (no ``alive/world`` token, no snapshot for ``WORLD_QUIET_S``), the
frames are sampled from the UAVs' round reports instead (``field.FieldView``): a swarm of
real or emulated vehicles is drawn from what its daemons say their vehicles report.

Callbacks only enqueue (``Mesh``); the pumps run on the loop and feed a ``FrameStore``.
"""

from __future__ import annotations

import asyncio
import logging
import time
from typing import TYPE_CHECKING, Any

from aeroweaver_edge.console.field import PERIOD_S, FieldView
from aeroweaver_edge.console.frames import FrameStore, report_decision, snapshot_frame
from aeroweaver_edge.contracts.wire import (
    ApprovalStatus,
    Assignment,
    Keys,
    MissionContext,
    ProgressReport,
    WorldSnapshot,
)
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_edge.safety.operator import record_dict

if TYPE_CHECKING:
    from aeroweaver_edge.mesh.session import Mesh, Subscription

log = logging.getLogger(__name__)
WORLD_QUIET_S = 5.0


def approval_dict(st: ApprovalStatus) -> dict[str, Any]:
    return {
        "uav": st.uav,
        "level": st.level,
        "pending": [{"action": p.action, "since": p.since, "skill": p.skill} for p in st.pending],
        "records": [record_dict(r) for r in st.records],
    }


class SwarmObserver:
    """Follows one swarm on an open mesh and keeps ``store`` current."""

    def __init__(
        self, mesh: Mesh, swarm: str, store: FrameStore, field_period_s: float = PERIOD_S
    ) -> None:
        self.mesh = mesh
        self.swarm = swarm
        self.keys = Keys(swarm)
        self.store = store
        self.alive: set[str] = set()  # every identity with a liveliness token
        self.uavs: set[str] = set()  # the UAV daemons among them
        self._context: MissionContext | None = None
        self._assign: dict[str, Assignment] = {}
        self._tasks: list[asyncio.Task[None]] = []
        self.field = FieldView()
        self.field_period_s = field_period_s
        self._world_at = -1e9  # monotonic time of the last world snapshot

    async def start(self) -> None:
        m, k = self.mesh, self.keys
        subs: dict[str, Subscription[Any]] = {
            "snapshot": m.subscribe(k.sim_snapshot, WorldSnapshot, maxsize=64),
            "reports": m.subscribe(k.report("*"), ProgressReport, maxsize=4096),
            "context": m.subscribe(k.context, MissionContext, maxsize=16),
            "assign": m.subscribe(k.assign("*"), Assignment, maxsize=256),
            "approvals": m.subscribe(k.approval_status("*"), ApprovalStatus, maxsize=256),
        }
        pumps = {
            "snapshot": self._on_snapshot, "reports": self._on_report,
            "context": self._on_context, "assign": self._on_assign,
            "approvals": self._on_approval,
        }  # fmt: skip
        for name, sub in subs.items():
            self._tasks.append(
                asyncio.create_task(self._pump(sub, pumps[name]), name=f"console-{name}")
            )
        watch = m.watch_liveliness(k.alive_all)
        self._tasks.append(asyncio.create_task(self._pump_alive(watch), name="console-alive"))
        self._tasks.append(asyncio.create_task(self._sample_field(), name="console-field"))
        self.store.update_meta(mode="live", swarm=self.swarm)
        await self.catch_up()

    async def catch_up(self) -> None:
        """What was published before we joined: the context, assignments, approvals."""
        for _k, ctx in await self.mesh.get(self.keys.context, MissionContext, timeout_s=1.0):
            self._on_context(ctx)
        for _k, a in await self.mesh.get(self.keys.assign("*"), Assignment, timeout_s=1.0):
            self._on_assign(a)
        got = await self.mesh.get(self.keys.approval_status("*"), ApprovalStatus, timeout_s=1.0)
        for _k, st in got:
            self._on_approval(st)

    async def aclose(self) -> None:
        await cancel_all(self._tasks)

    async def _pump(self, sub: Subscription[Any], handle: Any) -> None:
        async for _key, msg in sub:
            try:
                handle(msg)
            except Exception:  # a malformed but decodable payload must not end the view
                log.exception("console: %s dropped", type(msg).__name__)

    async def _pump_alive(self, watch: Any) -> None:
        prefix = self.keys.alive_uav("")
        async for key, alive in watch:
            name = key.rsplit("/", 1)[-1]
            (self.alive.add if alive else self.alive.discard)(name)
            if key.startswith(prefix):
                (self.uavs.add if alive else self.uavs.discard)(name)
            self.store.update_meta(alive=sorted(self.alive))

    @property
    def world(self) -> bool:
        """A simulated world is running (its token, or a recent snapshot)."""
        return "world" in self.alive or time.monotonic() - self._world_at < WORLD_QUIET_S

    async def _sample_field(self) -> None:
        """No world: a frame from the UAVs' latest reports every ``field_period_s``."""
        while True:
            await asyncio.sleep(self.field_period_s)
            if self.world:
                continue
            ctx = self._context
            frame = self.field.frame(ctx.task if ctx is not None else "")
            if frame is not None:
                if self.store.meta.get("source") != "field":
                    self.store.update_meta(source="field")
                self.store.add_frame(frame)

    # -- handlers (on the loop) ---------------------------------------------------------

    def _on_snapshot(self, snap: WorldSnapshot) -> None:
        if snap.h.sender != "world":
            return
        self._world_at = time.monotonic()
        if self.store.meta.get("task") != snap.task or "arena_half_m" not in self.store.meta:
            self.store.update_meta(
                task=snap.task, arena_half_m=snap.arena_half_m,
                comm_radius_m=snap.comm_radius_m, sensing_radius_m=snap.sensing_radius_m,
            )  # fmt: skip
        frame = snapshot_frame(snap)
        if self.field.flying:  # sim --link: the daemons also report their vehicle links
            frame["vehicles"] = self.field.vehicles()
        self.store.add_frame(frame)

    def _on_report(self, rep: ProgressReport) -> None:
        if rep.phase != "round" or rep.h.sender != rep.uav:
            return
        ctx = self._context
        if ctx is not None and rep.mission_id and rep.mission_id != ctx.mission_id:
            return  # another mission's report
        self.field.on_report(rep)
        if self.world or rep.vehicle is None:  # field frames carry their own decisions
            self.store.add_decision(rep.episode, rep.round, rep.uav, report_decision(rep))

    def _on_context(self, ctx: MissionContext) -> None:
        if ctx.h.sender != "cmdr":
            return
        cur = self._context
        if cur is not None and (ctx.h.epoch, ctx.h.seq) <= (cur.h.epoch, cur.h.seq):
            return
        self._context = ctx
        self.store.update_meta(
            mission={"id": ctx.mission_id, "task": ctx.task, "text": ctx.text,
                     "state": ctx.state, "constraints": list(ctx.constraints),
                     "participants": list(ctx.participants)},
        )  # fmt: skip
        self._publish_assignments()

    def _on_assign(self, a: Assignment) -> None:
        if a.h.sender != "cmdr":
            return
        cur = self._assign.get(a.uav)
        if cur is not None and (a.h.epoch, a.revision, a.h.seq) <= (
            cur.h.epoch, cur.revision, cur.h.seq,
        ):  # fmt: skip
            return
        self._assign[a.uav] = a
        self._publish_assignments()

    def _publish_assignments(self) -> None:
        ctx = self._context
        mine = {
            u: a for u, a in self._assign.items() if ctx is None or a.mission_id == ctx.mission_id
        }
        self.store.update_meta(
            roles={u: a.role for u, a in sorted(mine.items())},
            goals={u: a.local_goal for u, a in sorted(mine.items())},
            skills={u: list(a.skills) for u, a in sorted(mine.items())},
        )

    def _on_approval(self, st: ApprovalStatus) -> None:
        if st.h.sender != st.uav:
            return
        self.store.set_approvals(st.uav, approval_dict(st))


__all__ = ["SwarmObserver", "approval_dict"]
