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
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

from aeroweaver_edge import defaults as d
from aeroweaver_edge.config import ConfigError, LLMConfig, MeshConfig, SafetyConfig, SimConfig
from aeroweaver_edge.mesh import Mesh
from aeroweaver_edge.orchestration.planning import natural
from aeroweaver_edge.orchestration.swarm import until_stopped, world_task
from aeroweaver_edge.security.identity import COMMANDER, WORLD
from aeroweaver_edge.security.wiring import boot_headers
from aeroweaver_edge.sim.runner import RoundLog, WorldRunner
from commander.commander import Commander
from commander.harness import plan_from_text
from commander.mission_start import discover_roster, progress_row, watch_until
from commander.plan import MissionPlan
from commander.progress import ProgressBoard


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


async def start_mission(
    opts: MissionStartOptions,
    on_round: Callable[[RoundLog, ProgressBoard], Awaitable[None]] | None = None,
) -> dict[str, Any]:
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
            raise RuntimeError(
                f"no UAV daemon of swarm {opts.swarm!r} is up (waited {opts.roster_wait_s:.0f} s)"
            )
        out["roster"] = roster
        plan = opts.plan or await plan_from_text(opts.text, roster, opts.llm, opts.top_k)
        out["mission"] = plan.as_dict()
        commander = Commander(mesh, opts.swarm, headers)
        await commander.start()
        stack.push_async_callback(commander.aclose)
        commander.publish(plan)
        try:
            missing = await commander.wait_ready(plan.participants, 10.0)
            out["not_ready"] = sorted(missing)
            if opts.sim_world:
                task = world_task(plan, opts.max_rounds)
                cfg = SimConfig(
                    task=plan.task, uavs=task.n_uavs, seed=opts.seed,
                    max_rounds=opts.max_rounds, deadline_s=opts.deadline_s, pace_s=opts.pace_s,
                )  # fmt: skip

                async def hook(log: RoundLog) -> None:
                    if on_round is not None:
                        await on_round(log, commander.board)

                world_mesh, world_headers = mesh, None
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
                    res = await until_stopped(runner.run_episode(ep), commander)
                    if res is None:  # an operator stopped it (console, MCP)
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
                    if all(e["reason"] == "complete" for e in out["episodes"])
                    else "horizon"
                )
            else:

                async def watch() -> bool:
                    await watch_until(commander, plan.participants, opts.max_rounds)
                    return True

                done = await until_stopped(watch(), commander)
                out["ended"] = "horizon" if done else commander.end_reason
        except asyncio.CancelledError:
            # Ctrl-C / SIGTERM is the operator's stop: end the mission cleanly and report.
            out["ended"] = "operator stop"
            current = asyncio.current_task()
            if current is not None:
                current.uncancel()
        finally:
            commander.end_mission(str(out["ended"]))
            out["progress"] = {
                u: progress_row(p)
                for u, p in sorted(commander.board.uavs.items(), key=lambda kv: natural(kv[0]))
            }
            await asyncio.sleep(0.2)  # let the ended context leave before the session closes
    out["wall_s"] = round(time.monotonic() - started, 3)
    return out


__all__ = ["MissionStartOptions", "start_mission"]
