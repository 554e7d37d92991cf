"""A daemon gets its assignment however its link to the Commander and the Commander's
publish are ordered: it asks whenever the Commander's token appears and keeps asking (with
backoff) while it lacks its context or assignment, and drops both when the token goes.

The Commanders here only *serve* their plan (queryables) and never publish it, which is what
a daemon sees when the Commander's publish raced ahead of the daemon's link (the race phase
1 found in secured 10-UAV runs): only the daemon's own queries can get it the plan.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass, field

from aeroweaver_edge.config import AgentConfig, UavConfig
from aeroweaver_edge.contracts.wire import (
    Assignment,
    HeaderFactory,
    Keys,
    MissionContext,
    ProgressReport,
)
from aeroweaver_edge.daemon.app import run_daemon
from aeroweaver_edge.daemon.uav_daemon import UavDaemon
from aeroweaver_edge.mesh.session import Declared, Mesh
from tests.helpers.zenoh_net import ZenohNet, eventually

SWARM = "cu"
K = Keys(SWARM)


@dataclass
class QuietCommander:
    """Serves a plan on the Commander's queryables, holds the Commander's token, never puts."""

    mesh: Mesh
    headers: HeaderFactory = field(default_factory=lambda: HeaderFactory("cmdr"))
    context: MissionContext | None = None
    assignment: Assignment | None = None
    token: Declared | None = None
    asked: int = 0  # queries for uav0's assignment

    def serve(self) -> None:
        self.mesh.declare_queryable(K.context, lambda: self.context)
        self.mesh.declare_queryable(K.assign("uav0"), self._assignment)
        self.token = self.mesh.declare_token(K.alive_cmdr)

    def _assignment(self) -> Assignment | None:
        self.asked += 1
        return self.assignment

    def plan(self, mission_id: str) -> None:
        self.context = MissionContext(
            h=self.headers.next(), mission_id=mission_id, task="coverage", text="Cover."
        )
        self.assignment = Assignment(
            h=self.headers.next(), mission_id=mission_id, uav="uav0", role="searcher",
            local_goal="Cover a landmark.", skills=["hold_position"],
        )  # fmt: skip


@contextlib.asynccontextmanager
async def daemon(net: ZenohNet) -> AsyncIterator[UavDaemon]:
    ready: asyncio.Future[UavDaemon] = asyncio.get_running_loop().create_future()
    cfg = UavConfig(
        uav="uav0", swarm=SWARM, mesh=net.config(seed=False),
        agent=AgentConfig(selector="scripted", beta=0.0),
    )  # fmt: skip
    task = asyncio.create_task(run_daemon(cfg, on_ready=ready.set_result))
    try:
        yield await asyncio.wait_for(ready, 30.0)
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def test_a_plan_served_after_the_token_still_reaches_the_daemon(zenoh_net: ZenohNet) -> None:
    tap = await zenoh_net.open("observer")  # the seed; also taps the daemon's reports
    reports: list[ProgressReport] = []
    tap.subscribe(K.report("uav0"), ProgressReport, on_item=lambda item: reports.append(item[1]))
    first = QuietCommander(await zenoh_net.open("cmdr"))
    first.serve()  # token up, nothing to serve yet: the daemon's first queries get nothing
    async with daemon(zenoh_net) as d:
        # Asked at start-up and when the token appeared, and got nothing either time.
        assert await eventually(lambda: d.mission.commander_is_alive and first.asked >= 2, 10.0)
        assert d.mission.view() is None
        first.plan("m1")  # served, never published: only a retried query finds it
        assert await eventually(lambda: any(r.mission_id == "m1" for r in reports), 15.0)
        view = d.mission.view()
        assert view is not None
        assert (view.mission_id, view.role) == ("m1", "searcher")

        # The Commander leaves: its authority ends with its token, the UAV holds.
        await first.mesh.aclose()
        assert await eventually(lambda: d.mission.view() is None, 10.0)

        # A new Commander session (new epoch) that only serves its plan: caught up at once.
        second = QuietCommander(await zenoh_net.open("cmdr"))
        second.plan("m2")
        second.serve()
        assert await eventually(lambda: any(r.mission_id == "m2" for r in reports), 15.0)
        view = d.mission.view()
        assert view is not None
        assert view.mission_id == "m2"
        assert d.mission.rejected["old_epoch"] == 0
