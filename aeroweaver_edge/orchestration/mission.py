"""``aeroweaver mission start``: plan a mission for the daemons that are up, publish it and
watch it to its end; with ``sim_world`` also run the kinematic world for daemons on the sim
backend, flying the plan's task with the plan's roles.

The mission text is parsed once, against the live roster. The Commander never flies: it
publishes context and assignments and reads reports. Ending the mission (termination,
horizon or Ctrl-C) publishes the ended context, so every UAV holds.

In a secured swarm (``mesh.security``, e.g. from ``--keys``) the Commander runs as the
``cmdr`` identity with its boot counter, and the world, when run here, as ``world`` on its
own session (``world_mesh``): only the world identity may publish under ``sim/``.
"""

from __future__ import annotations

import asyncio
import contextlib
import secrets
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field, replace
from typing import Any, TypeVar

from aeroweaver_edge.config import ConfigError, LLMConfig, MeshConfig, SafetyConfig, SimConfig
from aeroweaver_edge.contracts import defaults as d
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.contracts.wire import Keys, ProgressReport
from aeroweaver_edge.mesh.secured import boot_headers
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.orchestration.contact import ContactWatch
from aeroweaver_edge.orchestration.planning import natural
from aeroweaver_edge.orchestration.run_health import mission_security
from aeroweaver_edge.orchestration.swarm import until_stopped, world_task
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_edge.security.identity import COMMANDER, WORLD
from aeroweaver_edge.sim.runner import RoundLog, WorldRunner
from aeroweaver_edge.vehicle.sim import WAITING_FOR_WORLD
from commander.commander import Commander
from commander.harness import plan_from_text
from commander.mission_start import discover_roster, progress_row
from commander.plan import MissionPlan
from commander.progress import ProgressBoard

T = TypeVar("T")


LOST_GRACE_S = 10.0


@dataclass(frozen=True)
class MissionStartOptions:
    text: str
    swarm: str = "default"
    mesh: MeshConfig = field(default_factory=MeshConfig)
    llm: LLMConfig | None = None  # None: rule-based parsing and template roles only
    roster_wait_s: float = 3.0
    top_k: int = d.TOP_K
    sim_world: bool = False
    seed: int = 1
    episodes: int = 1
    max_rounds: int = d.MAX_ROUNDS
    deadline_s: float = d.DEADLINE_S
    world_mesh: MeshConfig | None = None  # the world's own session (secured); None: shares ours
    safety: SafetyConfig = field(default_factory=SafetyConfig)  # the envelope the world checks
    plan: MissionPlan | None = None  # planned earlier against the live roster (``aeroweaver mcp``)
    pace_s: float = 0.0  # sim world: wall-clock floor per round
    lost_grace_s: float = LOST_GRACE_S  # every UAV out of contact this long: the mission stops


@dataclass
class MissionHooks:
    """What the terminal (or a test) is told as the mission goes: the plan before it is
    published, each accepted report, each world round."""

    on_plan: Callable[[dict[str, Any]], None] | None = None
    on_report: Callable[[ProgressReport], None] | None = None
    on_round: Callable[[RoundLog, ProgressBoard], Awaitable[None]] | None = None


def unique_id(mission_id: str) -> str:
    """Every start is its own mission: the plan's id (task and a digest of text and UAVs)
    plus the start time and a random part, so the same text twice never shares an id (a
    daemon would take the second for the first; records and logs would mix them)."""
    return f"{mission_id}-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}-{secrets.token_hex(2)}"


async def _world_is_up(mesh: Mesh, swarm: str, wait_s: float = 0.5) -> bool:
    """Whether a simulated world's liveliness token is up (someone else runs a world)."""
    watch = mesh.watch_liveliness(Keys(swarm).alive_world)
    try:
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(wait_s):
                async for _key, up in watch:
                    if up:
                        return True
        return False
    finally:
        await watch.aclose()


def _refuse_worldless(waiting: dict[str, str], plan: MissionPlan) -> None:
    stuck = sorted(u for u in plan.participants if waiting.get(u, "").startswith(WAITING_FOR_WORLD))
    if stuck:
        raise UserError(
            f"{', '.join(stuck)} fly the sim backend and are waiting for a simulated world, "
            "which nobody runs",
            "pass --sim-world to run it here, or give the daemons a flight link "
            '([vehicle] backend = "mavlink" and url in their uav.toml)',
        )


async def start_mission(
    opts: MissionStartOptions,
    on_round: Callable[[RoundLog, ProgressBoard], Awaitable[None]] | None = None,
    hooks: MissionHooks | None = None,
) -> dict[str, Any]:
    hooks = hooks or MissionHooks()
    on_round = on_round or hooks.on_round
    started = time.monotonic()
    out: dict[str, Any] = {"text": opts.text, "episodes": [], "ended": "not started"}
    if opts.sim_world and opts.mesh.security is not None and opts.world_mesh is None:
        raise ConfigError("a secured mission with the sim world needs the world identity's mesh")
    async with contextlib.AsyncExitStack() as stack:
        mesh = await Mesh.open(opts.mesh, node_id=COMMANDER)
        stack.push_async_callback(mesh.aclose)
        headers = await asyncio.to_thread(boot_headers, opts.mesh, COMMANDER)
        roster = await discover_roster(mesh, opts.swarm, opts.roster_wait_s)
        if not roster:
            raise UserError(
                f"no UAV daemon of swarm {opts.swarm!r} answered within {opts.roster_wait_s:g} s",
                "start them (aeroweaver daemon --config uav.toml), and check --swarm and "
                "--connect (or --keys) against their [mesh]",
            )
        out["roster"] = roster
        plan = opts.plan or await plan_from_text(opts.text, roster, opts.llm, opts.top_k)
        if opts.plan is None:
            plan = replace(plan, mission_id=unique_id(plan.mission_id))
        out["mission"] = plan.as_dict()
        if hooks.on_plan is not None:
            hooks.on_plan(out["mission"])
        commander = Commander(mesh, opts.swarm, headers)
        waiting: dict[str, str] = {}  # uav -> what its ready report says it waits for
        before: dict[str, dict[str, int]] = {}  # uav -> its refusals when it took the mission

        def heard(rep: ProgressReport) -> None:
            if rep.phase == "ready":
                before.setdefault(rep.uav, dict(rep.rejected))
                if rep.hold_reason:
                    waiting[rep.uav] = rep.hold_reason
            if hooks.on_report is not None:
                hooks.on_report(rep)

        commander.report_listeners.append(heard)
        await commander.start()
        stack.push_async_callback(commander.aclose)

        def where(uav: str) -> tuple[int, int]:
            p = commander.board.uavs.get(uav)
            return (p.last.episode, p.last.round) if p is not None and p.last else (0, -1)

        contact = ContactWatch(mesh, opts.swarm, plan.participants, where)
        contact.start()
        stack.push_async_callback(contact.aclose)
        commander.publish(plan)
        runner: WorldRunner | None = None
        world_mesh = mesh
        try:
            missing = await commander.wait_ready(plan.participants, 10.0)
            out["not_ready"] = sorted(missing)
            if not opts.sim_world and not await _world_is_up(mesh, opts.swarm):
                _refuse_worldless(waiting, plan)
            if opts.sim_world:
                task = world_task(plan, opts.max_rounds)
                cfg = SimConfig(
                    task=plan.task, uavs=task.n_uavs, seed=opts.seed,
                    max_rounds=opts.max_rounds, deadline_s=opts.deadline_s, pace_s=opts.pace_s,
                )  # fmt: skip

                async def hook(log: RoundLog) -> None:
                    if on_round is not None:
                        await on_round(log, commander.board)

                world_headers = None
                if opts.world_mesh is not None:
                    world_mesh = await Mesh.open(opts.world_mesh, node_id=WORLD)
                    stack.push_async_callback(world_mesh.aclose)
                    world_headers = await asyncio.to_thread(boot_headers, opts.world_mesh, WORLD)
                runner = WorldRunner(
                    world_mesh, opts.swarm, task, cfg, on_round=hook, headers=world_headers,
                    safety=opts.safety,
                )  # fmt: skip
                await runner.start()
                stack.push_async_callback(runner.aclose)
                # The world's end, told to every daemon, before its session closes: a
                # service daemon lands and waits for the next mission at once.
                stack.callback(runner.shutdown)
                await runner.wait_alive(plan.participants, 10.0)
                for ep in range(opts.episodes):
                    res = await _unless_lost(runner.run_episode(ep), commander, contact, opts)
                    if res is None:  # stopped: an operator (console, MCP), or no UAV left
                        break
                    out["episodes"].append(
                        {"episode": ep, "rounds": res.rounds, "reason": res.reason,
                         "team_return": res.team_mean_return,
                         "agent_returns": {u: res.returns[u] for u in task.uav_ids},
                         "scripted_returns": {b: res.returns[b] for b in task.scripted_ids}}
                    )  # fmt: skip
                out["envelope_violations"] = runner.envelope.summary()
                out["ended"] = commander.end_reason or (
                    "complete"
                    if out["episodes"] and all(e["reason"] == "complete" for e in out["episodes"])
                    else "horizon"
                )
            else:
                done = await _unless_lost(
                    _watch_rounds(commander, contact, opts.max_rounds), commander, contact, opts
                )
                out["ended"] = "horizon" if done else commander.end_reason
        except asyncio.CancelledError:
            # Ctrl-C / SIGTERM is the operator's stop: end the mission cleanly and report.
            out["ended"] = "operator stop"
            current = asyncio.current_task()
            if current is not None:
                current.uncancel()
        finally:
            commander.end_mission(str(out["ended"]))
            if not opts.sim_world and commander.board.uavs:  # the field's one episode
                out["episodes"].append(field_episode(commander.board, str(out["ended"])))
            out["progress"] = {
                u: progress_row(p)
                for u, p in sorted(commander.board.uavs.items(), key=lambda kv: natural(kv[0]))
            }
            out.update(_contact_fields(contact, runner))
            out["security"] = mission_security(mesh, world_mesh, commander.board, runner, before)
            await asyncio.sleep(0.2)  # let the ended context leave before the session closes
    out["wall_s"] = round(time.monotonic() - started, 3)
    return out


def field_episode(board: ProgressBoard, reason: str) -> dict[str, Any]:
    """A field mission's one episode, from the UAVs' own round reports (no world scores
    it): rounds, holds by cause, decision tokens and, where the daemons' reward source gave
    rewards, returns (``None`` otherwise: the field's ``NoRewards``)."""
    uavs = sorted(board.uavs.values(), key=lambda p: natural(p.uav))
    returns = {p.uav: (p.reward_sum if p.rewarded else None) for p in uavs}
    scored = [r for r in returns.values() if r is not None]
    causes: dict[str, int] = {}
    for p in uavs:
        for cause, n in p.holds_by_cause.items():
            causes[cause] = causes.get(cause, 0) + n
    return {
        "episode": 0,
        "rounds": max((p.reports for p in uavs), default=0),
        "reason": reason,
        "team_return": sum(scored) / len(scored) if scored else None,
        "agent_returns": returns,
        "source": "field: the UAVs' round reports",
        "decisions": sum(p.reports for p in uavs),
        "holds": sum(p.holds for p in uavs),
        "holds_by_cause": causes,
        "tokens": {
            "prompt": sum(p.prompt_tokens for p in uavs),
            "prompt_cached": sum(p.prompt_cached for p in uavs),
            "completion": sum(p.completion_tokens for p in uavs),
        },
        "llm_calls": sum(p.llm_calls for p in uavs),
    }


def _contact_fields(contact: ContactWatch, runner: WorldRunner | None) -> dict[str, Any]:
    """``lost_uavs`` (uav -> [episode, round] where it was lost) and ``rejoined_uavs`` (uav
    -> times it came back), as in a ``sim`` summary; the world's view where it ran (it
    knows the round), the Commander's otherwise; ``out_of_contact``: lost and not back."""
    lost = dict(contact.lost)
    rejoined = dict(contact.rejoined)
    if runner is not None:
        lost.update({u: list(w) for u, w in runner.stats.lost.items()})
        for u, n in runner.stats.rejoined.items():
            rejoined[u] = max(n, rejoined.get(u, 0))
    return {
        "lost_uavs": dict(sorted(lost.items(), key=lambda kv: natural(kv[0]))),
        "rejoined_uavs": dict(sorted(rejoined.items(), key=lambda kv: natural(kv[0]))),
        "out_of_contact": contact.out_of_contact,
    }


async def _watch_rounds(commander: Commander, contact: ContactWatch, rounds: int) -> bool:
    """Field mode: until every participant in contact reported ``rounds`` rounds (a lost
    one is not waited for: it holds by itself; the record names it)."""
    while True:
        flying = [u for u in contact.participants if u not in contact.lost or u in contact.alive]
        if flying and all(
            (p := commander.board.uavs.get(u)) is not None and p.reports >= rounds for u in flying
        ):
            return True
        commander.report_event.clear()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(1.0):  # contact changes do not set the report event
                await commander.report_event.wait()


async def _unless_lost(
    work: Awaitable[T], commander: Commander, contact: ContactWatch, opts: MissionStartOptions
) -> T | None:
    """``work`` until it ends, an operator stops the mission, or every participant has been
    out of contact for ``opts.lost_grace_s`` (then the mission ends as lost: None)."""

    async def all_lost() -> None:
        await contact.wait_all_lost(opts.lost_grace_s)
        commander.end_mission(
            f"lost contact with every UAV ({', '.join(contact.out_of_contact)}) for "
            f"{opts.lost_grace_s:g} s"
        )

    guard = asyncio.create_task(all_lost(), name="cmdr-all-lost")
    try:
        return await until_stopped(work, commander)
    finally:
        await cancel_all([guard])


__all__ = ["MissionHooks", "MissionStartOptions", "start_mission", "unique_id"]
