"""A whole simulated swarm on one machine: world + N daemons + Commander over loopback Zenoh.

Every daemon has its own Zenoh session, either as a task in this event loop or, with
``processes=True``, as its own OS process started with ``aeroweaver daemon`` (spawned, so no
Zenoh session is ever forked). Both modes run the same code and, for a deterministic
selector, give the same returns for the same seed.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import socket
import sys
import tempfile
import time
import uuid
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from aeroweaver_edge.app import run_daemon
from aeroweaver_edge.config import AgentConfig, LLMConfig, MeshConfig, SimConfig, UavConfig
from aeroweaver_edge.mesh import Mesh
from aeroweaver_edge.sim.episode import EpisodeResult
from aeroweaver_edge.sim.runner import RoundLog, WorldRunner
from aeroweaver_edge.sim.tasks import make_task
from aeroweaver_edge.skills import load_skills
from commander.commander import Commander
from commander.harness import plan_from_text
from commander.plan import MissionPlan, template_plan
from commander.progress import ProgressBoard

HONESTY_NOTE = {
    "scripted": "Decisions come from a scripted heuristic scorer, not an LLM: these returns say "
    "nothing about LLM quality.",
    "embedded": "Decisions come from SmolLM2-135M (embedded plumbing demo; strong position bias, "
    "no useful judgement): these returns are not evidence about LLM-driven swarm performance.",
    "endpoint": "Decisions come from the configured LLM endpoint.",
}


@dataclass(frozen=True)
class SwarmOptions:
    task: str = "coverage"
    uavs: int = 3
    seed: int = 1
    episodes: int = 1
    max_rounds: int = 24
    processes: bool = False
    selector: Literal["llm", "scripted"] = "llm"
    llm: LLMConfig = field(default_factory=LLMConfig)
    beta: float = 0.8
    gamma: float = 0.95
    memory_dir: Path | None = None  # None: a fresh temporary directory per run
    share_experience: bool = True
    deadline_s: float = 30.0
    mission_text: str | None = None
    top_k: int = 8  # task skills activated per UAV by the Commander (plus hold_position)
    swarm: str = "sim"
    slots: bool | None = None  # pin UAV i to llama-server slot i; None: embedded server only
    history_rounds: int = 8  # AgentConfig.history_rounds (0: no interaction history)
    state_context: bool = True  # AgentConfig.state_context (False: pose and entities only)


@dataclass
class RunSummary:
    task: str
    seed: int
    uavs: int
    mode: str
    selector: str
    episodes: list[dict[str, Any]] = field(default_factory=list)
    messages_sent: int = 0
    messages_dropped: int = 0
    decode_errors: int = 0
    holds: int = 0
    deadline_misses: int = 0
    lost_uavs: dict[str, list[int]] = field(default_factory=dict)
    wall_s: float = 0.0
    model: str | None = None
    probe: str | None = None
    tokens: dict[str, int] = field(default_factory=dict)
    setup_tokens: int = 0
    llm_calls: int = 0
    note: str = ""
    mission: dict[str, Any] | None = None
    tokens_by_agent: dict[str, int] = field(default_factory=dict)
    tokens_by_role: dict[str, int] = field(default_factory=dict)
    decision_latency_s: dict[str, float] = field(default_factory=dict)
    tokens_per_decision: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        eps = self.episodes
        agents = sorted({a for e in eps for a in e["agent_returns"]})
        return {
            "task": self.task,
            "seed": self.seed,
            "uavs": self.uavs,
            "mode": self.mode,
            "selector": self.selector,
            "model": self.model,
            "probe": self.probe,
            "rounds": sum(e["rounds"] for e in eps),
            # With several episodes the top-level returns are means over episodes.
            "team_return": _mean([e["team_return"] for e in eps]),
            "agent_returns": {a: _mean([e["agent_returns"][a] for e in eps]) for a in agents},
            "episodes": eps,
            "messages_sent": self.messages_sent,
            "messages_dropped": self.messages_dropped,
            "decode_errors": self.decode_errors,
            "holds": self.holds,
            "deadline_misses": self.deadline_misses,
            "lost_uavs": self.lost_uavs,
            "tokens": self.tokens,
            "tokens_per_decision": self.tokens_per_decision,
            "tokens_by_agent": self.tokens_by_agent,
            "tokens_by_role": self.tokens_by_role,
            "decision_latency_s": self.decision_latency_s,
            "setup_tokens": self.setup_tokens,
            "mission": self.mission,
            "llm_calls": self.llm_calls,
            "wall_s": round(self.wall_s, 3),
            "note": self.note,
        }


def _mean(xs: list[float]) -> float:
    return math.fsum(xs) / len(xs) if xs else math.nan


def _percentiles(xs: list[float]) -> dict[str, float]:
    """Round latency (observe to act, inside the daemon) over every decision of the run."""
    if not xs:
        return {}
    ys = sorted(xs)

    def at(q: float) -> float:
        return round(ys[min(len(ys) - 1, round(q * (len(ys) - 1)))], 4)

    return {"p50": at(0.5), "p95": at(0.95), "max": at(1.0)}


def _per_decision(prompt: int, cached: int, completion: int, calls: int) -> dict[str, float]:
    """Mean tokens per LLM decision; ``prompt_uncached`` is what the endpoint had to process."""
    if not calls:
        return {}
    return {
        "prompt": round(prompt / calls, 1),
        "prompt_cached": round(cached / calls, 1),
        "prompt_uncached": round((prompt - cached) / calls, 1),
        "completion": round(completion / calls, 2),
    }


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _mesh_configs(namespace: str) -> tuple[MeshConfig, MeshConfig]:
    port = free_port()
    seed = MeshConfig(listen=[f"tcp/127.0.0.1:{port}"], namespace=namespace)
    peer = MeshConfig(
        listen=["tcp/127.0.0.1:0"], connect=[f"tcp/127.0.0.1:{port}"], namespace=namespace
    )
    return seed, peer


def _episode_dict(ep: int, res: EpisodeResult, board: ProgressBoard) -> dict[str, Any]:
    return {
        "episode": ep,
        "rounds": res.rounds,
        "reason": res.reason,
        "team_return": res.team_mean_return,
        "agent_returns": dict(sorted(res.returns.items())),
        "metrics": res.metrics,
    }


class _Daemons:
    """Starts and stops the swarm's daemons, in this loop or as OS processes."""

    def __init__(self, configs: list[UavConfig], processes: bool, workdir: Path) -> None:
        self.configs = configs
        self.processes = processes
        self.workdir = workdir
        self.tasks: dict[str, asyncio.Task[Any]] = {}
        self.procs: dict[str, asyncio.subprocess.Process] = {}

    async def start(self) -> None:
        registry = load_skills()
        for cfg in self.configs:
            if self.processes:
                path = self.workdir / f"{cfg.uav}.json"
                path.write_text(cfg.model_dump_json(indent=2), encoding="utf-8")
                log = (self.workdir / f"{cfg.uav}.log").open("wb")  # the child inherits it
                self.procs[cfg.uav] = await asyncio.create_subprocess_exec(
                    sys.executable,
                    "-m",
                    "aeroweaver_edge.cli",
                    "daemon",
                    "--config",
                    str(path),
                    stdin=asyncio.subprocess.DEVNULL,
                    stdout=log,
                    stderr=log,
                )
                log.close()
            else:
                self.tasks[cfg.uav] = asyncio.create_task(
                    run_daemon(cfg, registry=registry), name=cfg.uav
                )

    async def kill(self, uav: str) -> None:
        """Fault injection: the daemon dies abruptly (process SIGKILL, or task cancelled)."""
        if uav in self.procs:
            self.procs[uav].kill()
            await self.procs[uav].wait()
        elif uav in self.tasks:
            self.tasks[uav].cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self.tasks[uav]

    def failed(self) -> dict[str, str]:
        """Daemons that ended before the run did, with the reason."""
        out: dict[str, str] = {}
        for uav, t in self.tasks.items():
            if t.done() and not t.cancelled() and t.exception() is not None:
                out[uav] = repr(t.exception())
        for uav, p in self.procs.items():
            if p.returncode not in (None, 0):
                tail = (self.workdir / f"{uav}.log").read_text(errors="replace")[-2000:]
                out[uav] = f"exit {p.returncode}: {tail}"
        return out

    async def stop(self, timeout_s: float = 15.0) -> None:
        waits = [*self.tasks.values()]
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                await asyncio.gather(
                    *waits, *(p.wait() for p in self.procs.values()), return_exceptions=True
                )
        for t in self.tasks.values():
            t.cancel()
        await asyncio.gather(*self.tasks.values(), return_exceptions=True)
        for p in self.procs.values():
            if p.returncode is None:
                p.kill()
                await p.wait()


@contextlib.asynccontextmanager
async def _shared_llm(opts: SwarmOptions) -> AsyncIterator[tuple[LLMConfig, str]]:
    """One LLM endpoint for the whole swarm: the configured one, or the embedded server."""
    if opts.selector != "llm":
        yield opts.llm, "scripted"
        return
    if opts.llm.base_url is not None:
        yield opts.llm, "endpoint"
        return
    from aeroweaver_edge.llm.embedded import EmbeddedServer

    # One cache slot per UAV; run_swarm pins each daemon to its slot (LLMConfig.slot).
    async with EmbeddedServer(n_parallel=max(1, opts.uavs)) as server:
        yield (
            opts.llm.model_copy(update={"base_url": server.base_url, "model": server.model}),
            "embedded",
        )


async def _seed_slots(llm: LLMConfig, plan: MissionPlan, uavs: list[str], *, history: bool) -> None:
    """Compute each role's prompt prefix once and copy it into its UAVs' slots (UAV i uses
    slot i), so round 0 does not process the same system prompt once per UAV."""
    from aeroweaver_edge.agent.prompt import prefix_messages
    from aeroweaver_edge.llm.slot_seed import SlotGroup, seed_slots
    from aeroweaver_edge.observation import MissionView

    registry = load_skills()
    groups: dict[tuple[str, str, tuple[str, ...]], tuple[list[dict[str, str]], list[int]]] = {}
    pinned = [(uav, a) for uav, a in plan.assignments.items() if uav in uavs]
    for uav, a in sorted(pinned, key=lambda item: uavs.index(item[0])):
        key = (a.role, a.local_goal, tuple(a.skills))
        if key not in groups:
            view = MissionView(plan.mission_id, plan.task, plan.text, a.role, a.local_goal,
                               tuple(a.skills), tuple(plan.constraints))  # fmt: skip
            docs = [registry.get(s).prompt_text() for s in a.skills if s in registry]
            groups[key] = (prefix_messages(view, uav, docs, history=history), [])
        groups[key][1].append(uavs.index(uav))
    assert llm.base_url is not None
    root = llm.base_url[: -len("/v1")] if llm.base_url.endswith("/v1") else llm.base_url
    await seed_slots(root, llm.model, [SlotGroup(m, slots) for m, slots in groups.values()])


async def _probe(llm: LLMConfig) -> str:
    from aeroweaver_edge.llm.client import ChatClient
    from aeroweaver_edge.llm.probe import probe_endpoint

    async with ChatClient.from_config(llm) as client:
        return (await probe_endpoint(client)).summary()


async def run_swarm(
    opts: SwarmOptions,
    *,
    on_round: Callable[[RoundLog, ProgressBoard], Awaitable[None]] | None = None,
    plan_factory: Callable[[list[str]], Awaitable[MissionPlan]] | None = None,
    fault: Callable[[RoundLog, _Daemons], Awaitable[None]] | None = None,
    on_commander: Callable[[Commander], None] | None = None,
) -> RunSummary:
    started = time.monotonic()
    task = make_task(opts.task, opts.uavs, max_rounds=opts.max_rounds)
    sim_cfg = SimConfig(
        task=opts.task,
        uavs=opts.uavs,
        seed=opts.seed,
        max_rounds=opts.max_rounds,
        deadline_s=opts.deadline_s,
    )
    namespace = f"aw-{uuid.uuid4().hex[:10]}"
    seed_mesh_cfg, peer_mesh_cfg = _mesh_configs(namespace)
    uavs = task.uav_ids
    summary = RunSummary(
        opts.task,
        opts.seed,
        opts.uavs,
        "processes" if opts.processes else "in-process",
        opts.selector,
    )

    async with contextlib.AsyncExitStack() as stack:
        tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="aeroweaver-")))
        memory_dir = opts.memory_dir or tmp
        memory_dir.mkdir(parents=True, exist_ok=True)
        llm, source = await stack.enter_async_context(_shared_llm(opts))
        summary.note = HONESTY_NOTE[source]
        if opts.selector == "llm":
            summary.model = llm.model
            summary.probe = await _probe(llm)
            summary.selector = f"llm:{llm.model}"
        else:
            summary.selector = "scripted:nearest-uncovered"

        world_mesh = await Mesh.open(seed_mesh_cfg, node_id="world")
        stack.push_async_callback(world_mesh.aclose)
        cmdr_mesh = await Mesh.open(peer_mesh_cfg, node_id="cmdr")
        stack.push_async_callback(cmdr_mesh.aclose)

        board_ref: dict[str, ProgressBoard] = {}

        async def round_hook(log: RoundLog) -> None:
            if fault is not None:
                await fault(log, daemons)
            if on_round is not None:
                await on_round(log, board_ref["board"])

        runner = WorldRunner(world_mesh, opts.swarm, task, sim_cfg, on_round=round_hook)
        await runner.start()
        stack.push_async_callback(runner.aclose)
        commander = Commander(cmdr_mesh, opts.swarm)
        await commander.start()
        stack.push_async_callback(commander.aclose)
        if on_commander is not None:
            on_commander(commander)

        pin_slots = source == "embedded" if opts.slots is None else opts.slots
        pin_slots = pin_slots and source != "scripted"
        configs = [
            UavConfig(
                uav=u,
                swarm=opts.swarm,
                mesh=peer_mesh_cfg,
                llm=llm.model_copy(update={"slot": i}) if pin_slots else llm,
                agent=AgentConfig(
                    selector=opts.selector,
                    beta=opts.beta,
                    gamma=opts.gamma,
                    memory_path=str(memory_dir / f"{u}.sqlite3"),
                    share_experience=opts.share_experience,
                    history_rounds=opts.history_rounds,
                    state_context=opts.state_context,
                ),
            )
            for i, u in enumerate(uavs)
        ]
        daemons = _Daemons(configs, opts.processes, tmp)
        stack.push_async_callback(daemons.stop)
        await daemons.start()

        wait_s = 60.0 if opts.processes else 30.0
        missing = await runner.wait_alive(uavs, wait_s)
        if missing:
            raise RuntimeError(f"daemons not up: {sorted(missing)}; {daemons.failed()}")
        roster = sorted(runner.alive)
        if plan_factory is not None:
            plan = await plan_factory(roster)
        elif opts.mission_text is not None:
            planner_llm = llm if opts.selector == "llm" else None
            plan = await plan_from_text(opts.mission_text, roster, planner_llm, opts.top_k)
        else:
            plan = template_plan(opts.task, uavs, f"{opts.task}-s{opts.seed}")
        if plan.task != opts.task:
            raise ValueError(f"the mission is a {plan.task} mission but the world runs {opts.task}")
        summary.setup_tokens = plan.setup_tokens
        summary.mission = plan.as_dict()
        commander.publish(plan)
        board_ref["board"] = commander.board
        missing = await commander.wait_ready(plan.participants, wait_s)
        if missing:
            raise RuntimeError(f"daemons not ready: {sorted(missing)}; {daemons.failed()}")
        if pin_slots:  # best effort: needs llama-server's slot files (the embedded one has them)
            await _seed_slots(llm, plan, uavs, history=opts.history_rounds > 0)

        try:
            for ep in range(opts.episodes):
                result = await runner.run_episode(ep)
                summary.episodes.append(_episode_dict(ep, result, commander.board))
                if ep + 1 < opts.episodes:
                    # Let finalised experience reach same-role peers before the next episode.
                    await asyncio.sleep(0.3)
        except asyncio.CancelledError:
            # Operator stop (Ctrl-C / SIGTERM): every UAV is told to hold, then all close.
            commander.end_mission("operator stop")
            runner.shutdown()
            raise
        runner.shutdown()
        await daemons.stop()
        await asyncio.sleep(0.2)  # last reports

        board = commander.board
        summary.messages_sent = sum(p.messages_sent for p in board.uavs.values())
        summary.messages_dropped = sum(p.messages_dropped for p in board.uavs.values())
        summary.holds = sum(p.holds for p in board.uavs.values())
        summary.deadline_misses = runner.stats.deadline_misses
        summary.decode_errors = (
            world_mesh.codec.stats.total
            + cmdr_mesh.codec.stats.total
            + sum((p.last.decode_errors if p.last else 0) for p in board.uavs.values())
        )
        summary.lost_uavs = {u: list(where) for u, where in runner.stats.lost.items()}
        prompt = sum(p.prompt_tokens for p in board.uavs.values())
        cached = sum(p.prompt_cached for p in board.uavs.values())
        completion = sum(p.completion_tokens for p in board.uavs.values())
        summary.tokens = {
            "prompt": prompt,
            "prompt_cached": cached,
            "completion": completion,
            "total": prompt + completion,
        }
        summary.llm_calls = sum(p.llm_calls for p in board.uavs.values())
        summary.tokens_per_decision = _per_decision(prompt, cached, completion, summary.llm_calls)
        for e in summary.episodes:
            e["tokens"] = board.episode_tokens.get(e["episode"], 0)
        summary.tokens_by_agent = {
            u: p.prompt_tokens + p.completion_tokens for u, p in sorted(board.uavs.items())
        }
        by_role: dict[str, int] = {}
        for p in board.uavs.values():
            by_role[p.role] = by_role.get(p.role, 0) + p.prompt_tokens + p.completion_tokens
        summary.tokens_by_role = dict(sorted(by_role.items()))
        summary.decision_latency_s = _percentiles(
            [x for p in board.uavs.values() for x in p.latencies_s]
        )
    summary.wall_s = time.monotonic() - started
    return summary


def write_json(summary: RunSummary, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(summary.as_dict(), indent=2, default=str) + "\n", encoding="utf-8")
