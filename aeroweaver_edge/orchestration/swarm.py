"""A whole simulated swarm on one machine: world + N daemons + Commander over loopback Zenoh.

The one place that wires the three together (``aeroweaver sim``; the benchmark builds on it):
the plan is decided first (from the task name, or by parsing the mission text once), the
world flies that plan's task with that plan's roles, the Commander publishes the plan, and
one daemon per participant decides. Every daemon has its own Zenoh session, either as a task
in this event loop or, with ``processes=True``, as its own OS process started with
``aeroweaver daemon`` (spawned, so no Zenoh session is ever forked). Both modes run the same
code and, for a deterministic selector, give the same returns for the same seed.

Runs are secured by default (``network.py``): a throw-away PKI per run, TLS with mutual
authentication, the swarm ACL and signatures on every session; ``secure=False`` (``sim
--insecure``) keeps plain loopback TCP. Either way the summary's ``security`` object says
what protected the run and what every side refused.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
import uuid
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TypeVar

from aeroweaver_edge.agent import choices
from aeroweaver_edge.agent.memory.experience import new_run_id
from aeroweaver_edge.config import (
    AgentConfig,
    ApprovalConfig,
    LLMConfig,
    MeshConfig,
    SafetyConfig,
    SimConfig,
    UavConfig,
)
from aeroweaver_edge.contracts import defaults as d
from aeroweaver_edge.contracts.errors import RunFailed, UserError
from aeroweaver_edge.mesh.secured import boot_headers
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.orchestration.barrier import DEFAULT_TIMEOUT_S as BARRIER_TIMEOUT_S
from aeroweaver_edge.orchestration.barrier import ExperienceBarrier
from aeroweaver_edge.orchestration.central import CentralRole
from aeroweaver_edge.orchestration.daemons import DaemonSet, DaemonsFailed
from aeroweaver_edge.orchestration.llm import HONESTY_NOTE, probe, seed_role_slots, shared_llm
from aeroweaver_edge.orchestration.network import RunNetwork, run_network
from aeroweaver_edge.orchestration.network import free_port as free_port
from aeroweaver_edge.orchestration.planning import (
    WIDE_SLOT_CTX,
    natural,
    plan_run,
    uav_ids,
    with_full_catalogue,
    with_seeded_order,
)
from aeroweaver_edge.orchestration.run_health import health_fields, security_fields
from aeroweaver_edge.orchestration.trace import TraceRecorder
from aeroweaver_edge.runtime.json_out import write_json_file
from aeroweaver_edge.runtime.run_dir import RunDir, sweep_stale
from aeroweaver_edge.security.identity import CENTRAL, COMMANDER, WORLD
from aeroweaver_edge.sim.episode import EpisodeResult
from aeroweaver_edge.sim.runner import RoundLog, WorldRunner
from aeroweaver_edge.tasks import create, get_spec
from aeroweaver_edge.tasks.base import TaskDefinition
from commander.commander import Commander
from commander.plan import MissionPlan
from commander.progress import ProgressBoard

T = TypeVar("T")


@dataclass(frozen=True)
class SwarmOptions:
    task: str | None = None  # None: from the mission text, else coverage
    uavs: int | None = None  # None: the mission's count, else the task's default team
    seed: int = 1
    episodes: int = 1
    max_rounds: int = d.MAX_ROUNDS
    processes: bool = False
    selector: Literal["llm", "scripted"] = "llm"
    llm: LLMConfig = field(default_factory=LLMConfig)
    beta: float = d.BETA
    gamma: float = d.GAMMA
    memory_dir: Path | None = None  # None: a fresh temporary directory per run
    share_experience: bool = True
    share_every: Literal["episode", "round"] = "episode"  # AgentConfig.share_every
    deadline_s: float = d.DEADLINE_S
    mission_text: str | None = None
    top_k: int = d.TOP_K  # task skills activated per UAV by the Commander (plus hold_position)
    swarm: str = "sim"
    measure_rss: bool = False  # read every daemon process's peak RSS before it exits
    link: Literal["sim", "mavlink", "mavsdk"] = "sim"  # flight: real MAVLink to emulated autopilots
    personality: str = "px4"  # the emulated autopilots' (with a mavlink/mavsdk link)
    slots: bool | None = None  # pin UAV i to llama-server slot i; None: embedded server only
    history_rounds: int = d.HISTORY_ROUNDS  # AgentConfig.history_rounds (0: no history)
    state_context: bool = True  # AgentConfig.state_context (False: pose and entities only)
    trace_path: Path | None = None  # write the per-round trace here (JSONL, docs/traces.md)
    secure: bool = True  # TLS (mutual) + ACL + signatures with per-run identities
    safety: SafetyConfig = field(default_factory=SafetyConfig)  # the daemons'; the world checks it
    # Benchmark conditions (docs/benchmark.md): a central node chooses for every UAV
    # (orchestration.central; the lab's baselines; selector must be "llm"); "full"
    # activation gives every UAV the whole task-skill catalogue (no role filter, no
    # top-K); coordination=False sends task messages only.
    central: CentralRole | None = None
    activation: Literal["topk", "full"] = "topk"
    coordination: bool = True
    # Option letters: "activation" (the Commander's order, the alphabet for the full
    # catalogue; sim and field) or "seeded" (the benchmark: a seeded order per task, seed and
    # UAV shared by every condition, orchestration.planning.with_seeded_order).
    option_order: Literal["activation", "seeded"] = "activation"
    finalised_only: bool = False  # AgentConfig.finalised_only (retrieval of ended episodes)
    # AgentConfig.estimator / .scripted_base; None: AEROWEAVER_ESTIMATOR /
    # AEROWEAVER_SCRIPTED_BASE if set, else the default (agent.choices)
    estimator: str | None = None
    scripted_base: str | None = None
    pace_s: float = 0.0  # wall-clock floor per round (the console: watchable scripted runs)
    approval: Literal["normal", "strict"] = "normal"  # daemons' [approval] level
    # Refuse to start when the LLM endpoint does not answer the start-up probe (the CLI's
    # sim and bench: every decision would be a hold). False: start anyway, as a fielded
    # daemon does, holding until the endpoint answers (the fault tests need that).
    require_llm_answer: bool = False


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
    deliveries: int = 0
    decode_errors: int = 0
    holds: int = 0
    holds_by_cause: dict[str, int] = field(default_factory=dict)
    deadline_misses: int = 0  # daemon side + world side (deadline_misses_by_side)
    deadline_misses_by_side: dict[str, int] = field(default_factory=dict)
    lost_uavs: dict[str, list[int]] = field(default_factory=dict)
    wall_s: float = 0.0
    model: str | None = None
    probe: str | None = None
    probe_kind: str | None = None  # the start-up probe's class
    llm_classes: dict[str, int] = field(default_factory=dict)  # UAVs per final class
    run_id: str = ""  # stamped on every experience record of this run
    tokens: dict[str, int] = field(default_factory=dict)
    setup_tokens: int = 0
    llm_calls: int = 0
    note: str = ""
    mission: dict[str, Any] | None = None
    roles: dict[str, str] = field(default_factory=dict)
    tokens_by_agent: dict[str, int] = field(default_factory=dict)
    tokens_by_role: dict[str, int] = field(default_factory=dict)
    decision_latency_s: dict[str, float] = field(default_factory=dict)
    tokens_per_decision: dict[str, float] = field(default_factory=dict)
    trace: str | None = None  # path of the per-round trace, when one was written
    decision_cpu_s: dict[str, float] = field(default_factory=dict)
    round_wall_s: list[float] = field(default_factory=list)
    peak_rss_kb: dict[str, int] = field(default_factory=dict)
    link: dict[str, Any] = field(default_factory=dict)  # flight link: what crossed MAVLink
    security: dict[str, Any] = field(default_factory=dict)  # security_fields()
    envelope_violations: dict[str, Any] = field(default_factory=dict)  # sim/envelope.py
    central: dict[str, Any] = field(default_factory=dict)  # a baseline's central node: totals
    tokens_by_side: dict[str, dict[str, int]] = field(default_factory=dict)  # uavs / central
    stopped: str | None = None  # the operator's stop (console, MCP), if the run ended so
    rejoined_uavs: dict[str, int] = field(default_factory=dict)  # uav -> times it came back
    experience_barrier: dict[str, Any] = field(default_factory=dict)  # BarrierStats.as_dict

    def as_dict(self) -> dict[str, Any]:
        eps = self.episodes
        agents = sorted({a for e in eps for a in e["agent_returns"]}, key=natural)
        scripted = sorted({a for e in eps for a in e.get("scripted_returns", {})})
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
            "scripted_returns": {
                a: _mean([e["scripted_returns"][a] for e in eps]) for a in scripted
            },
            "roles": self.roles,
            "episodes": eps,
            "messages_sent": self.messages_sent,
            "messages_dropped": self.messages_dropped,
            "deliveries": self.deliveries,
            "decode_errors": self.decode_errors,
            "holds": self.holds,
            "holds_by_cause": self.holds_by_cause,
            "deadline_misses": self.deadline_misses,
            "deadline_misses_by_side": self.deadline_misses_by_side,
            "lost_uavs": self.lost_uavs,
            "rejoined_uavs": self.rejoined_uavs,
            "experience_barrier": self.experience_barrier,
            "tokens": self.tokens,
            "tokens_per_decision": self.tokens_per_decision,
            "tokens_by_agent": self.tokens_by_agent,
            "tokens_by_role": self.tokens_by_role,
            "decision_latency_s": self.decision_latency_s,
            "decision_cpu_s": self.decision_cpu_s,
            "round_wall_s": percentiles(self.round_wall_s),
            "peak_rss_kb": self.peak_rss_kb,
            "setup_tokens": self.setup_tokens,
            "mission": self.mission,
            "llm_calls": self.llm_calls,
            "envelope_violations": self.envelope_violations,
            "llm_classes": self.llm_classes,
            "run_id": self.run_id,
            "wall_s": round(self.wall_s, 3),
            "note": self.note,
            "trace": self.trace,
            "security": self.security,
            **({"link": self.link} if self.link else {}),
            **({"central": self.central} if self.central else {}),
            **({"tokens_by_side": self.tokens_by_side} if self.tokens_by_side else {}),
            **({"stopped": self.stopped} if self.stopped else {}),
        }


def _mean(xs: list[float]) -> float | None:
    """Mean, or ``None`` (JSON null) when there is nothing to average: never NaN."""
    finite = [x for x in xs if math.isfinite(x)]
    return math.fsum(finite) / len(finite) if finite and len(finite) == len(xs) else None


def percentiles(xs: Iterable[float]) -> dict[str, float]:
    """p50, p95 and max (nearest rank), rounded to 0.1 ms."""
    ys: list[float] = sorted(xs)
    if not ys:
        return {}

    def at(q: float) -> float:
        return round(ys[min(len(ys) - 1, round(q * (len(ys) - 1)))], 4)

    return {"p50": at(0.5), "p95": at(0.95), "max": at(1.0)}


def _per_decision(prompt: int, cached: int, completion: int, calls: int) -> dict[str, float]:
    """Mean tokens per LLM request; ``prompt_uncached`` is what the endpoint had to process."""
    if not calls:
        return {}
    return {
        "prompt": round(prompt / calls, 1),
        "prompt_cached": round(cached / calls, 1),
        "prompt_uncached": round((prompt - cached) / calls, 1),
        "completion": round(completion / calls, 2),
    }


def mesh_configs(namespace: str, *, star: bool = True) -> tuple[MeshConfig, MeshConfig]:
    """(the world's, everyone else's) mesh settings on loopback.

    ``star``: the world's session is a Zenoh router and every daemon and the Commander a
    client of it, so each holds one link instead of one per peer (a full peer mesh is
    O(N^2) links, about 3 MB and a thread's worth of work per daemon at 50 UAVs); routing
    happens inside Zenoh, never in the world's Python. ``star=False``: a gossiping peer
    mesh around the world, as the field deployment uses.
    """
    port = free_port()
    if star:
        seed = MeshConfig(mode="router", listen=[f"tcp/127.0.0.1:{port}"], namespace=namespace)
        client = MeshConfig(
            mode="client", listen=[], connect=[f"tcp/127.0.0.1:{port}"], namespace=namespace
        )
        return seed, client
    seed = MeshConfig(listen=[f"tcp/127.0.0.1:{port}"], namespace=namespace)
    peer = MeshConfig(
        listen=["tcp/127.0.0.1:0"], connect=[f"tcp/127.0.0.1:{port}"], namespace=namespace
    )
    return seed, peer


def _episode_dict(ep: int, res: EpisodeResult, task: TaskDefinition) -> dict[str, Any]:
    ours = {u: res.returns[u] for u in sorted(task.uav_ids, key=natural)}
    theirs = {b: res.returns[b] for b in task.scripted_ids}
    return {
        "episode": ep,
        "rounds": res.rounds,
        "reason": res.reason,
        "team_return": res.team_mean_return,
        "agent_returns": ours,
        "scripted_returns": theirs,
        "metrics": res.metrics,
    }


def _trace_header(summary: RunSummary, opts: SwarmOptions, cfg: SimConfig) -> dict[str, Any]:
    """What a trace reader needs before the first round: who flies what, and where."""
    return {
        "task": summary.task,
        "seed": summary.seed,
        "uavs": summary.uavs,
        "selector": summary.selector,
        "model": summary.model,
        "note": summary.note,
        "run_id": summary.run_id,
        "roles": summary.roles,
        "mission": summary.mission,
        "beta": opts.beta,
        "option_order": opts.option_order,
        "round_s": cfg.round_s,
        "max_rounds": cfg.max_rounds,
        "arena_half_m": d.ARENA_HALF_M,
        "sensing_radius_m": cfg.sensing_radius_m,
        "comm_radius_m": d.COMM_RADIUS_M,
    }


@dataclass(frozen=True)
class SwarmHandle:
    """What an observer or operator next to a running swarm needs (``aeroweaver sim
    --console``): the swarm, its Commander, and the mesh settings for an identity of this
    run (``"observer"``, ``"operator"``); on plain loopback every identity gets the same."""

    swarm: str
    commander: Commander
    mesh_for: Callable[[str], MeshConfig]


async def until_stopped(work: Awaitable[T], commander: Commander) -> T | None:
    """``work``'s result, or None (``work`` cancelled) once the Commander's mission ended
    by an operator stop: the world stops flying rounds for a mission nobody flies."""
    job = asyncio.ensure_future(work)
    stop = asyncio.ensure_future(commander.ended.wait())
    try:
        await asyncio.wait({job, stop}, return_when=asyncio.FIRST_COMPLETED)
    except BaseException:  # we were cancelled: so is the work
        job.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await job
        raise
    finally:
        stop.cancel()
    if job.done():
        return job.result()
    job.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await job
    return None


def world_task(plan: MissionPlan, max_rounds: int) -> TaskDefinition:
    """The task definition the world flies for ``plan``: its task, its UAVs and roles."""
    roles = {u: plan.assignments[u].role for u in sorted(plan.assignments, key=natural)}
    return create(plan.task, roles, max_rounds=max_rounds)


async def run_swarm(
    opts: SwarmOptions,
    *,
    on_round: Callable[[RoundLog, ProgressBoard], Awaitable[None]] | None = None,
    plan_factory: Callable[[list[str]], Awaitable[MissionPlan]] | None = None,
    fault: Callable[[RoundLog, DaemonSet], Awaitable[None]] | None = None,
    on_commander: Callable[[Commander], None] | None = None,
    on_network: Callable[[RunNetwork], None] | None = None,
    on_started: Callable[[SwarmHandle], Awaitable[None]] | None = None,
    on_plan: Callable[[MissionPlan], None] | None = None,
) -> RunSummary:
    started = time.monotonic()
    # flag > environment > default, resolved once (a bad variable: one line, before any start)
    estimator = choices.resolve("estimator", opts.estimator)
    scripted_base = choices.resolve("scripted_base", opts.scripted_base)
    async with contextlib.AsyncExitStack() as stack:
        # One embedded-server cache slot per UAV we expect to fly (the plan is not made yet:
        # it may need the LLM); a larger mission shares slots round-robin.
        n_slots = opts.uavs or get_spec(opts.task or "coverage").team_size
        central_slot = n_slots if opts.central is not None else None  # its own cache slot
        wide = opts.central is not None or opts.activation == "full"  # 22 skill documents
        llm, source = await stack.enter_async_context(
            shared_llm(
                opts.llm,
                needed=opts.selector == "llm",
                n_parallel=n_slots + (central_slot is not None),
                slot_ctx=WIDE_SLOT_CTX if wide else None,
            )
        )
        if plan_factory is not None:
            plan = await plan_factory(uav_ids(opts.uavs or 3))
        else:
            plan = await plan_run(
                task=opts.task,
                uavs=opts.uavs,
                mission_text=opts.mission_text,
                llm=llm if opts.selector == "llm" else None,
                top_k=opts.top_k,
                mission_id=None if opts.mission_text else f"{opts.task or 'coverage'}-s{opts.seed}",
            )
        if opts.activation == "full":
            plan = with_full_catalogue(plan)
        if opts.option_order == "seeded":
            plan = with_seeded_order(plan, opts.seed)
        task = world_task(plan, opts.max_rounds)
        uavs = task.uav_ids
        summary = RunSummary(
            plan.task,
            opts.seed,
            len(uavs),
            "processes" if opts.processes else "in-process",
            opts.selector,
            roles=task.roles(),
            setup_tokens=plan.setup_tokens,
            mission=plan.as_dict(),
            note=HONESTY_NOTE[source],
            run_id=new_run_id(),  # one per run: its records never collide with another run's
        )
        if opts.central is not None and opts.selector != "llm":
            raise RunFailed(f"the {opts.central.selector} baseline needs an LLM (selector llm)")
        if opts.selector == "llm":
            summary.model = llm.model
            verdict = await probe(llm)
            if opts.require_llm_answer and not verdict.verdict:
                raise UserError(verdict.unanswered_line())
            summary.probe, summary.probe_kind = verdict.line(), verdict.kind
            summary.selector = f"llm:{llm.model}"
            if opts.central is not None:
                summary.selector = f"central:{opts.central.selector}:{llm.model}"
        else:
            summary.selector = f"scripted:{scripted_base}"
        if on_plan is not None:  # who flies what, before it flies (and after every refusal)
            on_plan(plan)
        sim_cfg = SimConfig(
            task=plan.task,
            uavs=len(uavs),
            seed=opts.seed,
            max_rounds=opts.max_rounds,
            deadline_s=opts.deadline_s,
            pace_s=opts.pace_s,
        )
        namespace = f"aw-{uuid.uuid4().hex[:10]}"
        # Runs killed earlier left their directories behind only if no daemon outlived
        # them; this run's is never left behind (run_dir.py).
        await asyncio.to_thread(sweep_stale)
        tmp = stack.enter_context(RunDir.create()).path
        memory_dir = opts.memory_dir or tmp
        memory_dir.mkdir(parents=True, exist_ok=True)
        net = await stack.enter_async_context(
            run_network(opts.secure, tmp / "pki", opts.swarm, namespace, uavs)
        )
        if on_network is not None:
            on_network(net)

        world_mesh = await Mesh.open(net.config(WORLD), node_id=WORLD)
        stack.push_async_callback(world_mesh.aclose)
        cmdr_mesh = await Mesh.open(net.config(COMMANDER), node_id=COMMANDER)
        stack.push_async_callback(cmdr_mesh.aclose)
        world_headers, cmdr_headers = await asyncio.gather(
            asyncio.to_thread(boot_headers, net.config(WORLD), WORLD),
            asyncio.to_thread(boot_headers, net.config(COMMANDER), COMMANDER),
        )

        board_ref: dict[str, ProgressBoard] = {}
        # The daemons that played the latest round: they share that episode's experience.
        last_round: set[str] = set()

        recorder = None
        if opts.trace_path is not None:
            recorder = TraceRecorder(opts.trace_path, _trace_header(summary, opts, sim_cfg))

        async def round_hook(log: RoundLog) -> None:
            if recorder is not None:
                recorder.on_round(log)
            summary.round_wall_s.append(log.wall_s)
            last_round.clear()
            last_round.update(log.commands)
            summary.deliveries += log.deliveries
            if fault is not None:
                await fault(log, daemons)
            if on_round is not None:
                await on_round(log, board_ref["board"])

        linked = None  # flight: emulated autopilots behind real MAVLink (docs/flight.md)
        if opts.link != "sim":
            from aeroweaver_edge.sim.emulator.swarm_link import emulated_swarm

            linked = await stack.enter_async_context(
                emulated_swarm(opts.link, task, sim_cfg, opts.personality)
            )
        runner = WorldRunner(
            world_mesh, opts.swarm, task, sim_cfg, on_round=round_hook,
            vehicles=linked.bridge if linked else None, headers=world_headers,
            safety=opts.safety,
        )  # fmt: skip
        await runner.start()
        stack.push_async_callback(runner.aclose)
        commander = Commander(cmdr_mesh, opts.swarm, cmdr_headers)
        if recorder is not None:
            commander.report_listeners.append(recorder.on_report)
        await commander.start()
        stack.push_async_callback(commander.aclose)
        if on_commander is not None:
            on_commander(commander)
        if on_started is not None:  # observers join before the first round
            await on_started(SwarmHandle(opts.swarm, commander, net.config))
        barrier = ExperienceBarrier(max(BARRIER_TIMEOUT_S, 2 * opts.deadline_s))
        commander.report_listeners.append(barrier.on_report)

        pin_slots = source == "embedded" if opts.slots is None else opts.slots
        pin_slots = pin_slots and source != "scripted"
        central = None
        if opts.central is not None:
            central_llm = llm.model_copy(update={"slot": central_slot}) if pin_slots else llm
            central = await stack.enter_async_context(
                opts.central.open(
                    net.config(CENTRAL),
                    opts.swarm,
                    central_llm,
                    recorder.on_central if recorder is not None else None,
                )
            )
        configs = [
            UavConfig(
                uav=u,
                swarm=opts.swarm,
                mesh=net.config(u),
                llm=llm.model_copy(update={"slot": i % n_slots}) if pin_slots else llm,
                agent=AgentConfig(
                    selector=opts.selector if opts.central is None else opts.central.selector,
                    beta=opts.beta,
                    gamma=opts.gamma,
                    memory_path=str(memory_dir / f"{u}.sqlite3"),
                    run_id=summary.run_id,
                    share_experience=opts.share_experience,
                    share_every=opts.share_every,
                    history_rounds=opts.history_rounds,
                    state_context=opts.state_context,
                    coordination_reports=opts.coordination,
                    finalised_only=opts.finalised_only,
                    estimator=estimator,
                    scripted_base=scripted_base,
                ),
                safety=opts.safety,
                approval=ApprovalConfig(level=opts.approval),
                **({"vehicle": linked.vehicles[u]} if linked else {}),
            )
            for i, u in enumerate(uavs)
        ]
        daemons = DaemonSet(configs, opts.processes, tmp)
        stack.push_async_callback(daemons.stop)
        await daemons.start()

        # Start-up is CPU-bound (each process imports the runtime): allow for a loaded machine.
        wait_s = (20.0 + 3.0 * len(uavs)) if opts.processes else (30.0 + 0.5 * len(uavs))
        try:  # a daemon that exits at start-up is reported at once, with its own line
            missing = await daemons.unless_one_fails(runner.wait_alive(uavs, wait_s))
            if missing:
                raise RunFailed(f"daemons not up: {sorted(missing)}; {daemons.failed()}")
            commander.publish(plan)
            board_ref["board"] = commander.board
            ready = commander.wait_ready(plan.participants, wait_s)
            missing = await daemons.unless_one_fails(ready)
            if missing:
                raise RunFailed(f"daemons not ready: {sorted(missing)}; {daemons.failed()}")
        except DaemonsFailed as exc:
            runner.shutdown()  # the run is over: the others are not "lost"
            daemons.terminate()  # and would wait for a mission until stop's timeout
            raise RunFailed(f"daemon failed at start-up: {exc}") from None
        if pin_slots and opts.central is None:  # best effort: needs llama-server slot files
            await seed_role_slots(llm, plan, uavs, n_slots, history=opts.history_rounds > 0)

        try:
            for ep in range(opts.episodes):
                result = await until_stopped(runner.run_episode(ep), commander)
                if result is None:  # an operator stopped the mission (console, MCP)
                    summary.stopped = commander.end_reason
                    break
                summary.episodes.append(_episode_dict(ep, result, task))
                if recorder is not None:
                    recorder.on_episode(ep, result)
                if opts.share_experience:
                    # Finalised experience is in every same-role peer before the next
                    # episode (and, after the last, before the daemons store and stop).
                    await barrier.wait(ep, last_round, lambda: set(runner.alive))
        except asyncio.CancelledError:
            # Operator stop (Ctrl-C / SIGTERM): every UAV is told to hold, then all close.
            commander.end_mission("operator stop")
            runner.shutdown()
            raise
        if opts.measure_rss:
            summary.peak_rss_kb = daemons.peak_rss_kb()
        if linked is not None:
            summary.link = linked.report(opts.link)
            linked.bridge.detach()  # landing after the run flies on the emulator's own clock
        runner.shutdown()
        await daemons.stop()
        failed = daemons.failed()
        if failed:
            raise RunFailed(
                f"{len(failed)} daemon(s) stopped during the run: "
                + "; ".join(f"{u}: {_last_line(why)}" for u, why in sorted(failed.items()))
            )
        await asyncio.sleep(0.2)  # last reports

        board = commander.board
        summary.messages_sent = sum(p.messages_sent for p in board.uavs.values())
        summary.messages_dropped = sum(p.messages_dropped for p in board.uavs.values())
        summary.holds = sum(p.holds for p in board.uavs.values())
        health = health_fields(
            board, runner.stats.deadline_misses, summary.probe, summary.probe_kind
        )
        summary.holds_by_cause = health["holds_by_cause"]
        summary.deadline_misses_by_side = health["deadline_misses_by_side"]
        summary.deadline_misses = summary.deadline_misses_by_side["total"]
        summary.llm_classes = health["llm_classes"]
        summary.probe = health["probe"]
        summary.decode_errors = (
            world_mesh.codec.stats.total
            + cmdr_mesh.codec.stats.total
            + sum((p.last.decode_errors if p.last else 0) for p in board.uavs.values())
        )
        summary.lost_uavs = {u: list(where) for u, where in runner.stats.lost.items()}
        summary.envelope_violations = runner.envelope.summary()
        summary.rejoined_uavs = dict(runner.stats.rejoined)
        summary.experience_barrier = barrier.stats.as_dict() if opts.share_experience else {}
        prompt = sum(p.prompt_tokens for p in board.uavs.values())
        completion = sum(p.completion_tokens for p in board.uavs.values())
        cached = sum(p.prompt_cached for p in board.uavs.values())
        summary.tokens = {
            "prompt": prompt,
            "prompt_cached": cached,
            "completion": completion,
            "total": prompt + completion,
        }
        summary.llm_calls = health["llm_calls"]
        summary.tokens_per_decision = _per_decision(prompt, cached, completion, summary.llm_calls)
        for e in summary.episodes:
            e["tokens"] = board.episode_tokens.get(e["episode"], 0)
        if central is not None:  # counted where spent: the UAVs' (local) and the central node's
            summary.central = central.totals()
            fold_central_tokens(summary, summary.central)
        summary.tokens_by_agent = {
            u: p.prompt_tokens + p.completion_tokens
            for u, p in sorted(board.uavs.items(), key=lambda kv: natural(kv[0]))
        }
        by_role: dict[str, int] = {}
        for p in board.uavs.values():
            by_role[p.role] = by_role.get(p.role, 0) + p.prompt_tokens + p.completion_tokens
        summary.tokens_by_role = dict(sorted(by_role.items()))
        summary.decision_latency_s = percentiles(
            [x for p in board.uavs.values() for x in p.latencies_s]
        )
        summary.decision_cpu_s = percentiles([x for p in board.uavs.values() for x in p.cpu_s])
        summary.security = security_fields(world_mesh, cmdr_mesh, runner, board)
        if recorder is not None:
            summary.trace = str(recorder.write())
    summary.wall_s = time.monotonic() - started
    return summary


def fold_central_tokens(summary: RunSummary, central: dict[str, Any]) -> None:
    """Fold the central node's tokens and calls into ``summary`` (totals and per episode),
    keeping the split in ``tokens_by_side`` (the UAVs' own calls vs the central node's)."""
    uav_side = dict(summary.tokens)
    ct = central["tokens"]
    summary.tokens_by_side = {"uavs": uav_side, "central": dict(ct)}
    summary.tokens = {k: uav_side.get(k, 0) + ct.get(k, 0) for k in uav_side}
    summary.llm_calls += central["llm_calls"]
    calls = summary.llm_calls
    if calls:
        t = summary.tokens
        summary.tokens_per_decision = {
            "prompt": round(t["prompt"] / calls, 1),
            "prompt_cached": round(t["prompt_cached"] / calls, 1),
            "prompt_uncached": round((t["prompt"] - t["prompt_cached"]) / calls, 1),
            "completion": round(t["completion"] / calls, 2),
        }
    for e in summary.episodes:
        e["tokens"] += central["by_episode"].get(str(e["episode"]), {}).get("tokens", 0)


def write_json(summary: RunSummary, path: Path) -> None:
    """Strict JSON (never NaN), written atomically: a reader never sees half a file."""
    write_json_file(path, summary.as_dict())


def _last_line(text: str) -> str:
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else text


__all__ = [
    "RunSummary",
    "SwarmHandle",
    "SwarmOptions",
    "fold_central_tokens",
    "percentiles",
    "run_swarm",
    "until_stopped",
    "world_task",
    "write_json",
]
