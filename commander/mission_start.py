"""``aeroweaver mission start``: plan a mission for the daemons that are up, publish it and
watch it to its end. Optionally runs the kinematic world for daemons on the sim backend.

The Commander never flies: it publishes context and assignments and reads reports. Ending
the mission (termination, horizon or Ctrl-C) publishes the ended context, so every UAV holds.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

from aeroweaver_edge.config import LLMConfig, MeshConfig, SimConfig
from aeroweaver_edge.mesh import Mesh
from aeroweaver_edge.sim.runner import RoundLog, WorldRunner
from aeroweaver_edge.sim.tasks import TASKS, make_task
from aeroweaver_edge.wire import Keys, last_chunk
from commander.commander import Commander
from commander.harness import plan_from_text
from commander.progress import ProgressBoard, UavProgress


@dataclass(frozen=True)
class MissionStartOptions:
    text: str
    swarm: str = "default"
    mesh: MeshConfig = field(default_factory=MeshConfig)
    llm: LLMConfig | None = None  # None: rule-based parsing and template roles only
    roster_wait_s: float = 3.0
    top_k: int = 8
    sim_world: bool = False
    seed: int = 1
    episodes: int = 1
    max_rounds: int = 24
    deadline_s: float = 30.0


async def discover_roster(mesh: Mesh, swarm: str, wait_s: float) -> list[str]:
    """UAV ids whose liveliness tokens are seen within ``wait_s``."""
    alive: set[str] = set()
    watch = mesh.watch_liveliness(Keys(swarm).alive_uav("*"))
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(wait_s):
            async for key, up in watch:
                (alive.add if up else alive.discard)(last_chunk(key))
    await watch.aclose()
    return sorted(alive)


async def start_mission(
    opts: MissionStartOptions,
    on_round: Callable[[RoundLog, ProgressBoard], Awaitable[None]] | None = None,
) -> dict[str, Any]:
    started = time.monotonic()
    out: dict[str, Any] = {"text": opts.text, "episodes": [], "ended": "not started"}
    async with contextlib.AsyncExitStack() as stack:
        mesh = await Mesh.open(opts.mesh, node_id="cmdr")
        stack.push_async_callback(mesh.aclose)
        roster = await discover_roster(mesh, opts.swarm, opts.roster_wait_s)
        if not roster:
            raise RuntimeError(
                f"no UAV daemon of swarm {opts.swarm!r} is up (waited {opts.roster_wait_s:.0f} s)"
            )
        out["roster"] = roster
        plan = await plan_from_text(opts.text, roster, opts.llm, opts.top_k)
        out["mission"] = plan.as_dict()
        commander = Commander(mesh, opts.swarm)
        await commander.start()
        stack.push_async_callback(commander.aclose)
        commander.publish(plan)
        try:
            missing = await commander.wait_ready(plan.participants, 10.0)
            out["not_ready"] = sorted(missing)
            if opts.sim_world:
                if plan.task not in TASKS:
                    raise RuntimeError(f"the simulator has no {plan.task} world yet")
                task = make_task(plan.task, len(plan.participants), max_rounds=opts.max_rounds)
                if task.uav_ids != plan.participants:
                    raise RuntimeError(
                        f"the sim world flies {task.uav_ids}; the mission has {plan.participants}"
                    )
                cfg = SimConfig(
                    task=plan.task, uavs=len(plan.participants), seed=opts.seed,
                    max_rounds=opts.max_rounds, deadline_s=opts.deadline_s,
                )  # fmt: skip

                async def hook(log: RoundLog) -> None:
                    if on_round is not None:
                        await on_round(log, commander.board)

                runner = WorldRunner(mesh, opts.swarm, task, cfg, on_round=hook)
                await runner.start()
                stack.push_async_callback(runner.aclose)
                await runner.wait_alive(plan.participants, 10.0)
                for ep in range(opts.episodes):
                    res = await runner.run_episode(ep)
                    out["episodes"].append(
                        {"episode": ep, "rounds": res.rounds, "reason": res.reason,
                         "team_return": res.team_mean_return, "agent_returns": res.returns}
                    )  # fmt: skip
                out["ended"] = (
                    "complete"
                    if all(e["reason"] == "complete" for e in out["episodes"])
                    else "horizon"
                )
            else:
                await _watch_until(commander, plan.participants, opts.max_rounds)
                out["ended"] = "horizon"
        except asyncio.CancelledError:
            # Ctrl-C / SIGTERM is the operator's stop: end the mission cleanly and report.
            out["ended"] = "operator stop"
            current = asyncio.current_task()
            if current is not None:
                current.uncancel()
        finally:
            commander.end_mission(str(out["ended"]))
            out["progress"] = {u: _progress(p) for u, p in sorted(commander.board.uavs.items())}
            await asyncio.sleep(0.2)  # let the ended context leave before the session closes
    out["wall_s"] = round(time.monotonic() - started, 3)
    return out


def _progress(p: UavProgress) -> dict[str, Any]:
    return {
        "role": p.role,
        "reports": p.reports,
        "holds": p.holds,
        "last": p.last.invocation if p.last else None,
        "prompt_tokens": p.prompt_tokens,
        "completion_tokens": p.completion_tokens,
    }


async def _watch_until(commander: Commander, uavs: list[str], rounds: int) -> None:
    """Field mode: the mission runs until every participant reported ``rounds`` rounds."""
    while not all(
        (p := commander.board.uavs.get(u)) is not None and p.reports >= rounds for u in uavs
    ):
        commander.report_event.clear()
        await commander.report_event.wait()
