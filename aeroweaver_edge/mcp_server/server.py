"""``aeroweaver mcp``: the swarm as a Model Context Protocol server (official SDK, 2.x line:
``mcp.server.mcpserver.MCPServer``), over stdio or streamable HTTP.

Resources (read-only, from the console's observer on the mesh):

* ``aeroweaver://roster`` the UAV daemons that are up, their roles, the Commander and world;
* ``aeroweaver://uav/{uav}/state`` one UAV: position, velocity, role, goal, its last
  decision (options, base scores, advantages, pick, hold and its cause), approvals;
* ``aeroweaver://mission`` the mission context, roles, local goals, active skills;
* ``aeroweaver://decisions/last`` every UAV's decision in the last round;
* ``aeroweaver://approvals`` vehicle actions waiting for an operator, and the records.

* ``aeroweaver://tasks`` the tasks a mission text can name, with an example text each.

Tools: ``plan_mission`` (parse mission text against the live roster and show the plan;
changes nothing), ``start_mission``, ``stop_mission``, ``approve_action`` and ``uav_trace``.
The acting three first answer with what they *will* do and the exact ``confirm`` phrase,
after checking the same preconditions as the real call (a dry run never promises what the
call would refuse); only a call carrying that phrase and the operator token does it. They
act as an operator does (operator keys; the Commander stops the mission, the UAV checks its
approval); starting a mission makes this server the mission's Commander (the ``cmdr``
identity on a secured swarm, and ``world`` for the simulated world), as ``aeroweaver mission
start`` does. Every refusal or failure is a tool error (``isError``) with one line
(``errors.py``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import secrets
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Any

from mcp.server.mcpserver import MCPServer
from mcp.server.mcpserver.exceptions import ToolError

from aeroweaver_edge.config import LLMConfig, MeshConfig
from aeroweaver_edge.console.frames import FrameStore
from aeroweaver_edge.console.observer import SwarmObserver
from aeroweaver_edge.contracts import defaults as d
from aeroweaver_edge.contracts.wire import VehicleActionKind
from aeroweaver_edge.mcp_server.errors import AgentServer
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.orchestration.planning import natural
from aeroweaver_edge.safety.approval import approve_phrase
from aeroweaver_edge.safety.operator import OPERATOR, OperatorLink, record_dict
from commander.plan import MissionPlan

log = logging.getLogger(__name__)
READ_ONLY = "this MCP server is read-only: no operator token is configured"
COMMANDER = "cmdr"  # security.identity.COMMANDER (not imported: no security import here)
START_WAIT_S = 15.0  # start_mission: until the mission's context is seen on the mesh
MAX_TTL_S = 86_400.0


@dataclass(frozen=True)
class McpOptions:
    swarm: str
    mesh: MeshConfig
    commander_mesh: MeshConfig | None = None  # start_mission's Commander session (None: mesh)
    world_mesh: MeshConfig | None = None  # the sim world's session (secured: the world identity)
    operator_token: str | None = None  # None: the acting tools refuse
    sim_world: bool = False  # start_mission also flies the kinematic world
    pace_s: float = 0.0
    max_rounds: int = d.MAX_ROUNDS
    top_k: int = d.TOP_K
    llm: LLMConfig | None = None  # planning: rules and templates only when None
    name: str = "aeroweaver"


@dataclass
class SwarmService:
    """The server's side of the swarm: an observer's frames, an operator link, the plans
    it showed and the mission it started (if any)."""

    opts: McpOptions
    store: FrameStore = field(default_factory=FrameStore)
    plans: dict[str, MissionPlan] = field(default_factory=dict)
    mission: asyncio.Task[dict[str, Any]] | None = None
    run: dict[str, Any] = field(default_factory=dict)  # the mission started here: its state
    _mesh: Mesh | None = None
    _observer: SwarmObserver | None = None
    _op: OperatorLink | None = None

    async def start(self) -> None:
        cfg = self.opts.mesh
        name = cfg.security.identity if cfg.security is not None else OPERATOR
        self._mesh = await Mesh.open(cfg, node_id=name)
        self._observer = SwarmObserver(self._mesh, self.opts.swarm, self.store)
        await self._observer.start()
        self._op = OperatorLink(self._mesh, self.opts.swarm, person=f"mcp:{name}")

    async def aclose(self) -> None:
        if self.mission is not None:
            self.mission.cancel()  # the mission's own Commander ends it cleanly
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self.mission
        if self._observer is not None:
            await self._observer.aclose()
        if self._mesh is not None:
            await self._mesh.aclose()

    @property
    def op(self) -> OperatorLink:
        assert self._op is not None, "service not started"
        return self._op

    @property
    def observer(self) -> SwarmObserver:
        assert self._observer is not None, "service not started"
        return self._observer

    # -- views ----------------------------------------------------------------------------

    def roster(self) -> dict[str, Any]:
        meta = self.store.meta
        roles = meta.get("roles") or {}
        uavs = sorted(self.observer.uavs, key=natural)
        return {
            "swarm": self.opts.swarm,
            "uavs": [{"id": u, "role": roles.get(u, "")} for u in uavs],
            "commander": "cmdr" in self.observer.alive,
            "world": "world" in self.observer.alive,
        }

    def last_frame(self) -> dict[str, Any] | None:
        return self.store.frame(self.store.last_index)

    def uav_state(self, uav: str) -> dict[str, Any]:
        frame = self.last_frame()
        body = next((b for b in (frame or {}).get("bodies", []) if b["id"] == uav), None)
        meta = self.store.meta
        return {
            "uav": uav,
            "alive": uav in self.observer.uavs,
            "round": None if frame is None else {"episode": frame["episode"],
                                                 "round": frame["round"]},
            "pos_m": None if body is None else body["pos"],
            "vel_mps": None if body is None else body.get("vel", [0.0, 0.0]),
            "role": (meta.get("roles") or {}).get(uav, ""),
            "goal": (meta.get("goals") or {}).get(uav, ""),
            "skills": (meta.get("skills") or {}).get(uav, []),
            "held": None if frame is None else uav in frame.get("held", []),
            "decision": None if frame is None else frame["decisions"].get(uav),
            "approvals": self.store.approvals.get(uav),
        }  # fmt: skip

    def trace(self, uav: str, rounds: int) -> list[dict[str, Any]]:
        out = []
        for frame in self.store.since(self.store.last_index - rounds + 1):
            body = next((b for b in frame["bodies"] if b["id"] == uav), None)
            dec = frame["decisions"].get(uav) or {}
            out.append({
                "episode": frame["episode"], "round": frame["round"],
                "pos_m": body["pos"] if body else None,
                "reward": frame["rewards"].get(uav),
                "invocation": dec.get("invocation"), "held": uav in frame["held"],
                "hold_cause": dec.get("hold_cause"), "options": dec.get("options"),
                "base": dec.get("base"), "advantage": dec.get("advantage"),
                "chosen": dec.get("chosen"), "reason": dec.get("reason"),
            })  # fmt: skip
        return out

    # -- preconditions: the dry run and the real call check the same ones -----------------

    def check_acting(self) -> None:
        if self.opts.operator_token is None:
            raise ToolError(READ_ONLY)
        sec = self._mesh.security if self._mesh is not None else None
        if sec is not None and sec.role.value != OPERATOR:  # the ACL would drop its writes
            raise ToolError(
                f"this server joined the secured swarm as {sec.config.identity!r} "
                f"({sec.role.value}), which may not act: start it with --identity operator"
            )

    def check_token(self, token: str) -> None:
        self.check_acting()
        assert self.opts.operator_token is not None
        if not secrets.compare_digest(token.encode(), self.opts.operator_token.encode()):
            raise ToolError("wrong operator token")

    def known_plan(self, plan_id: str) -> MissionPlan:
        plan = self.plans.get(plan_id)
        if plan is None:
            known = ", ".join(self.plans) or "none yet"
            raise ToolError(f"unknown plan {plan_id!r} (planned here: {known}); "
                            "call plan_mission first")  # fmt: skip
        return plan

    @property
    def commander_mesh(self) -> MeshConfig:
        return self.opts.commander_mesh or self.opts.mesh

    async def check_start(self, plan: MissionPlan) -> None:
        """Why ``start_mission`` would refuse ``plan`` now (ToolError), else nothing."""
        self.check_acting()
        if self.mission is not None and not self.mission.done():
            raise ToolError(f"this server already runs mission {self.run.get('id')}; "
                            "stop it first (stop_mission)")  # fmt: skip
        sec = self.commander_mesh.security
        if sec is not None and sec.identity != COMMANDER:
            raise ToolError(
                f"starting a mission on this secured swarm needs the {COMMANDER!r} identity, "
                f"not {sec.identity!r}: start the server with --keys DIR (a swarm directory "
                "with a cmdr identity) or --commander-config FILE"
            )
        if self.opts.sim_world and sec is not None and self.opts.world_mesh is None:
            raise ToolError(
                "--sim-world on a secured swarm needs the world identity's session: start the "
                "server with --keys DIR (a swarm directory with a world identity)"
            )
        missing = [u for u in plan.participants if u not in self.observer.uavs]
        if missing:
            raise ToolError(f"{', '.join(missing)} of plan {plan.mission_id} not on the mesh "
                            "any more: plan again (plan_mission)")  # fmt: skip
        if COMMANDER in self.observer.alive:
            ctx = await self.op.context()
            what = f" (mission {ctx.mission_id}, {ctx.state})" if ctx is not None else ""
            raise ToolError(f"another Commander is on the mesh{what}: stop it first")
        if self.opts.sim_world and "world" in self.observer.alive:
            raise ToolError("a simulated world already runs on this swarm: stop it first")

    async def check_approve(self, uav: str, ttl_s: float) -> None:
        self.check_acting()
        if not 0 < ttl_s <= MAX_TTL_S:
            raise ToolError(f"ttl_s {ttl_s:g}: must be within (0, {MAX_TTL_S:g}] seconds")
        if uav not in self.observer.uavs:
            up = ", ".join(sorted(self.observer.uavs, key=natural)) or "none"
            raise ToolError(f"{uav} is not on the mesh (UAVs up: {up})")

    # -- actions --------------------------------------------------------------------------

    async def plan(self, text: str) -> dict[str, Any]:
        from commander.harness import plan_from_text

        roster = sorted(self.observer.uavs, key=natural)
        if not roster:
            raise ToolError(f"no UAV daemon of swarm {self.opts.swarm!r} is up")
        plan = await plan_from_text(text, roster, self.opts.llm, self.opts.top_k)
        self.plans[plan.mission_id] = plan
        return {
            "plan_id": plan.mission_id,
            "plan": plan.as_dict(),
            "will": self.describe_start(plan),
            "confirm": f"start {plan.mission_id}",
        }

    def describe_start(self, plan: MissionPlan) -> str:
        world = " and fly the simulated world" if self.opts.sim_world else ""
        return (
            f"become the Commander of mission {plan.mission_id} ({plan.task}): publish its "
            f"context and the assignments of {', '.join(plan.participants)}{world}; each UAV "
            "then decides for itself. Stop it with stop_mission."
        )

    async def start_mission(self, plan: MissionPlan) -> dict[str, Any]:
        from aeroweaver_edge.orchestration.mission import MissionStartOptions, start_mission

        await self.check_start(plan)
        opts = MissionStartOptions(
            text=plan.text, swarm=self.opts.swarm, mesh=self.commander_mesh, plan=plan,
            sim_world=self.opts.sim_world, world_mesh=self.opts.world_mesh,
            max_rounds=self.opts.max_rounds, pace_s=self.opts.pace_s, roster_wait_s=1.0,
        )  # fmt: skip
        self.run = {"id": plan.mission_id, "state": "starting"}
        task = asyncio.create_task(start_mission(opts), name=f"mcp-{plan.mission_id}")
        task.add_done_callback(self._ended)
        self.mission = task
        try:
            async with asyncio.timeout(START_WAIT_S):
                while (self.store.meta.get("mission") or {}).get("id") != plan.mission_id:
                    if task.done():
                        task.result()  # raises why it stopped
                        raise ToolError(f"mission {plan.mission_id} ended at once: "
                                        f"{self.run.get('ended')}")  # fmt: skip
                    await self.store.wait_change(0.5)
        except TimeoutError:
            raise ToolError(f"mission {plan.mission_id} was not seen on the mesh within "
                            f"{START_WAIT_S:g} s; it may still start (read aeroweaver://mission)"
                            ) from None  # fmt: skip
        self.run["state"] = "running"
        return {"started": plan.mission_id, "participants": plan.participants}

    def _ended(self, task: asyncio.Task[dict[str, Any]]) -> None:
        """The mission's outcome for ``aeroweaver://mission`` (and no unretrieved error)."""
        if task.cancelled():
            self.run.update(state="cancelled")
            return
        exc = task.exception()
        if exc is not None:
            from aeroweaver_edge.contracts.errors import describe
            from aeroweaver_edge.runtime.redact import one_line

            described = describe(exc)
            why = described[1] if described else f"{type(exc).__name__}: {exc}"
            self.run.update(state="failed", error=one_line(why))
            return
        out = task.result()
        self.run.update(
            state="ended", ended=out.get("ended"), wall_s=out.get("wall_s"),
            not_ready=out.get("not_ready"), episodes=out.get("episodes", []),
        )  # fmt: skip


def build_server(service: SwarmService) -> MCPServer[Any]:
    server = AgentServer(
        service.opts.name,
        instructions=(
            "An AeroWeaver swarm: each UAV's daemon decides for itself. Read the resources to "
            "see it. Acting tools (start_mission, stop_mission, approve_action) answer first "
            "with what they will do and a confirm phrase (after checking what the real call "
            "checks); call again with confirm set to that phrase and the operator token to do "
            "it. A refusal or failure is a tool error whose text says why."
        ),
    )

    @server.resource("aeroweaver://roster", mime_type="application/json")
    def roster() -> dict[str, Any]:
        """The UAV daemons that are up, with their roles; is the Commander / world up."""
        return service.roster()

    @server.resource("aeroweaver://uav/{uav}/state", mime_type="application/json")
    def uav_state(uav: str) -> dict[str, Any]:
        """One UAV: pose, role, goal, active skills, hold, last decision, approvals."""
        return service.uav_state(uav)

    @server.resource("aeroweaver://mission", mime_type="application/json")
    def mission() -> dict[str, Any]:
        """The mission context and each UAV's role, local goal and active skills; ``run``:
        the mission this server started (state, how it ended, episodes, or why it failed)."""
        m = service.store.meta
        out = {k: m.get(k) for k in ("mission", "task", "roles", "goals", "skills")}
        out["run"] = dict(service.run) or None
        return out

    @server.resource("aeroweaver://decisions/last", mime_type="application/json")
    def last_decisions() -> dict[str, Any]:
        """Every UAV's decision in the last round (options, base scores, advantages, pick)."""
        frame = service.last_frame()
        if frame is None:
            return {"round": None, "decisions": {}}
        return {"episode": frame["episode"], "round": frame["round"],
                "decisions": frame["decisions"]}  # fmt: skip

    @server.resource("aeroweaver://approvals", mime_type="application/json")
    def approvals() -> dict[str, Any]:
        """Per UAV: approval level, vehicle actions waiting for an operator (``action``:
        takeoff, land or return_home; ``skill``: the skill that asked), records."""
        return dict(service.store.approvals)

    @server.resource("aeroweaver://tasks", mime_type="application/json")
    def tasks() -> dict[str, Any]:
        """The tasks a mission text can name (plan_mission), each with an example text."""
        from aeroweaver_edge.tasks import specs

        return {n: {"title": s.title, "summary": s.summary, "example": s.mission_text}
                for n, s in specs().items()}  # fmt: skip

    @server.tool()
    async def plan_mission(text: str) -> dict[str, Any]:
        """Plan a mission from natural-language text against the UAVs that are up and show
        the plan (task, roles, local goals, active skills). Changes nothing: start it with
        start_mission(plan_id, confirm=...). Known tasks: resource aeroweaver://tasks."""
        return await service.plan(text)

    @server.tool()
    async def start_mission(
        plan_id: str, confirm: str = "", operator_token: str = ""
    ) -> dict[str, Any]:
        """Start a planned mission: this server becomes its Commander (publishes context and
        assignments). Without confirm it checks and says what it will do."""
        plan = service.known_plan(plan_id)
        phrase = f"start {plan_id}"
        if confirm != phrase:
            await service.check_start(plan)
            return {"done": False, "will": service.describe_start(plan), "confirm": phrase}
        service.check_token(operator_token)
        return {"done": True, **await service.start_mission(plan)}

    @server.tool()
    async def stop_mission(
        confirm: str = "", reason: str = "", operator_token: str = ""
    ) -> dict[str, Any]:
        """Stop the current mission through its Commander: every UAV holds, then lands or
        returns home as configured. Without confirm it checks and says what it will do."""
        service.check_acting()
        plan = await service.op.plan_stop()
        phrase = f"stop {plan.mission_id}"
        if confirm != phrase:
            return {"done": False, "will": plan.describe(), "confirm": phrase}
        service.check_token(operator_token)
        note = await service.op.stop(plan, reason)
        return {"done": True, "stopped": plan.mission_id, "commander": note}

    @server.tool()
    async def approve_action(
        uav: str,
        action: VehicleActionKind,
        ttl_s: float = 300.0,
        confirm: str = "",
        operator_token: str = "",
    ) -> dict[str, Any]:
        """Approve a vehicle action (takeoff, land, return_home) for one UAV; it checks the
        approval, records it and it expires after ttl_s. Without confirm it checks and shows
        what is pending and what it will do."""
        await service.check_approve(uav, ttl_s)
        phrase = approve_phrase(uav, action)
        if confirm != phrase:
            status = service.store.approvals.get(uav)
            return {
                "done": False,
                "will": f"send {uav} an operator approval to {action} within {ttl_s:g} s of "
                "receipt; the UAV checks the sender, records it and uses it as its "
                "approval level says",
                "pending": status["pending"] if status else [],
                "level": status["level"] if status else None,
                "confirm": phrase,
            }
        service.check_token(operator_token)
        rec = await service.op.approve(uav, action, ttl_s)
        return {"done": True, "approval": record_dict(rec)}

    @server.tool()
    def uav_trace(uav: str, rounds: int = 10) -> dict[str, Any]:
        """A UAV's recent rounds (read-only): position, reward, decision with options,
        base scores, advantages, pick and reason, hold and its cause."""
        rounds = max(1, min(int(rounds), 500))
        return {"uav": uav, "rounds": service.trace(uav, rounds)}

    return server


@contextlib.asynccontextmanager
async def running(opts: McpOptions) -> AsyncIterator[tuple[SwarmService, MCPServer[Any]]]:
    service = SwarmService(opts)
    await service.start()
    try:
        yield service, build_server(service)
    finally:
        await service.aclose()


async def serve(
    opts: McpOptions, transport: str, host: str = "127.0.0.1", port: int = 8766
) -> None:
    """Serve until the client goes away (stdio) or until cancelled (http)."""
    async with running(opts) as (_service, server):
        if transport == "stdio":
            await server.run_stdio_async()
            return
        import uvicorn

        from aeroweaver_edge.console.server import _Server, bind

        sock = bind(host, port)
        app = server.streamable_http_app(host=host)
        config = uvicorn.Config(app, log_level="warning", timeout_graceful_shutdown=1)
        http = _Server(config)
        task = asyncio.ensure_future(http.serve(sockets=[sock]))
        try:
            await asyncio.shield(task)
        except asyncio.CancelledError:  # Ctrl-C: let uvicorn shut the app down, then go
            http.should_exit = True
            with contextlib.suppress(Exception):
                async with asyncio.timeout(5.0):
                    await task
            raise
        finally:
            sock.close()


__all__ = ["McpOptions", "SwarmService", "build_server", "running", "serve"]
