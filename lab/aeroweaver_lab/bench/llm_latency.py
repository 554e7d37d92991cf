"""In-episode decision latency of the embedded model:
``python -m aeroweaver_lab.bench.llm_latency`` (or ``aeroweaver bench llm_latency``).

It reproduces the shape of a simulated coverage episode without the world or the mesh:
N UAVs share one embedded llama.cpp server (one cache slot each, as ``aeroweaver sim``
sets it up) and decide round after round through the real ``LLMSelector`` and prompt
(static system part, each UAV's own append-only history, compact round tail). Their
observations come from a small deterministic flight towards three landmarks: entities in
sensing range, the peers' intent messages of the previous round (0.1 m bodies, as the
skills send them) and the candidates the real coverage skills offer. The UAVs of a round
decide concurrently, as in lockstep, or one after the other with ``--serial``.

Prints one JSON line: decision latency p50/p95, round wall p50, prompt tokens per decision
(uncached = processed by the server, cached = reused from the UAV's slot), overall and
without round 0 (the cold start), and the load average before and after. Figures are only
comparable on an idle machine (docs/notes/llm.md); the load is printed so a reader can tell.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import statistics
import sys
import time
from dataclasses import dataclass
from typing import Any

from aeroweaver_edge.agent.candidates import build_candidates
from aeroweaver_edge.agent.describe import describe
from aeroweaver_edge.agent.history import InteractionHistory
from aeroweaver_edge.agent.llm_selector import LLMSelector
from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.contracts.observation import Observation, VehicleState
from aeroweaver_edge.contracts.ports import DecisionRequest
from aeroweaver_edge.contracts.skill_api import SkillContext
from aeroweaver_edge.contracts.wire import Entity, Header, InboxMessage
from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.llm.embedded import EmbeddedServer, EmbeddedUnavailable
from aeroweaver_edge.skills import SkillRegistry, load_skills

SENSING_M = 45.0
COMM_M = 55.0
STEP_M = 5.5  # 11 m/s for a 0.5 s round
LANDMARKS = {"L0": (30.0, 25.0), "L1": (-35.0, 30.0), "L2": (10.0, -40.0)}
MISSION = "Cover every landmark with one drone each and hold there; avoid collisions."
ROLE = "searcher"
GOAL = "Reach a landmark no other drone is covering and stay within 3 m of it."
SKILLS = ("cover_landmark", "explore_local", "return_in_bounds", "hold_position")
CONSTRAINTS = ("stay inside the 140 m x 140 m arena", "keep at least 2 m from other drones")


def percentile(values: list[float], q: float) -> float:
    """Nearest-rank percentile (no interpolation: honest for small samples)."""
    ordered = sorted(values)
    rank = max(1, math.ceil(q / 100 * len(ordered)))
    return ordered[rank - 1]


@dataclass
class _Uav:
    uav: str
    index: int
    pos: tuple[float, float]
    target: str
    selector: LLMSelector
    history: InteractionHistory | None
    seq: int = 0


def _towards(pos: tuple[float, float], goal: tuple[float, float]) -> tuple[float, float]:
    dn, de = goal[0] - pos[0], goal[1] - pos[1]
    d = math.hypot(dn, de)
    if d <= STEP_M:
        return goal
    return (pos[0] + dn / d * STEP_M, pos[1] + de / d * STEP_M)


def _observation(me: _Uav, team: list[_Uav], episode: int, rnd: int) -> Observation:
    entities = [
        Entity(id=lid, kind="landmark", pos=(p[0], p[1], 0.0))
        for lid, p in LANDMARKS.items()
        if math.dist(me.pos, p) <= SENSING_M
    ]
    entities += [
        Entity(id=o.uav, kind="uav", pos=(o.pos[0], o.pos[1], -5.0), role=ROLE)
        for o in team
        if o is not me and math.dist(me.pos, o.pos) <= SENSING_M
    ]
    messages = []
    if rnd > 0:  # last round's intents of the peers within communication range
        for o in team:
            if o is me or math.dist(me.pos, o.pos) > COMM_M:
                continue
            lp = LANDMARKS[o.target]
            body: dict[str, str | int | float | bool] = {
                "skill": "cover_landmark",
                "target_id": o.target,
                "north": round(lp[0], 1),
                "east": round(lp[1], 1),
            }
            messages.append(
                InboxMessage(
                    h=Header(sender=o.uav, epoch=1, seq=o.seq, stamp=0.0),
                    to=me.uav,
                    round=rnd - 1,
                    kind="intent",
                    body=body,
                )
            )
    return Observation(
        me.uav,
        episode,
        rnd,
        VehicleState((me.pos[0], me.pos[1], -5.0), (STEP_M * 2, 0.0, 0.0)),
        tuple(sorted(entities, key=lambda e: (e.kind, e.id))),
        tuple(messages),
    )


def _request(me: _Uav, obs: Observation, registry: SkillRegistry) -> DecisionRequest:
    ctx = SkillContext(uav=me.uav, uav_index=me.index, role=ROLE, task="coverage")
    cs = build_candidates(registry, SKILLS, obs, ctx)
    return DecisionRequest(
        observation=obs,
        mission_text=MISSION,
        role=ROLE,
        local_goal=GOAL,
        constraints=CONSTRAINTS,
        skill_docs=[registry.get(s).prompt_text() for s in SKILLS],
        observation_text=describe(obs),
        candidates=cs.candidates,
        history=None if me.history is None else me.history.lines(obs.episode, obs.round),
    )


@dataclass
class _Decision:
    round: int
    latency_s: float
    prompt: int
    cached: int
    error: str | None


async def _decide(me: _Uav, request: DecisionRequest) -> _Decision:
    started = time.perf_counter()
    scores = await me.selector.score(request)
    latency = time.perf_counter() - started
    obs = request.observation
    if me.history is not None:
        best = max(scores.logprobs, key=lambda lb: scores.logprobs[lb], default=None)
        text = next((c.text for c in request.candidates if c.label == best), "hold_position()")
        me.history.record_decision(obs.episode, obs.round, text, best is not None)
        d = min(math.dist(me.pos, p) for p in LANDMARKS.values())
        me.history.record_reward(obs.episode, obs.round, -d / 70.0)  # mpe-like: -distance
    return _Decision(obs.round, latency, scores.prompt_tokens, scores.cached_tokens, scores.error)


async def run(
    uavs: int, rounds: int, history: int, slots: bool, serial: bool, threads: int | None
) -> dict[str, Any]:
    registry = load_skills()
    load_before = os.getloadavg()
    async with EmbeddedServer(n_parallel=uavs, threads=threads) as server:
        team: list[_Uav] = []
        for i in range(uavs):
            cfg = LLMConfig(
                base_url=server.base_url,
                model=server.model,
                deadline_s=120.0,
                slot=i if slots else None,
            )
            team.append(
                _Uav(
                    uav=f"uav{i}",
                    index=i,
                    pos=(-20.0 + 6.0 * i, -20.0 + 4.0 * i),
                    target=list(LANDMARKS)[i % len(LANDMARKS)],
                    selector=LLMSelector(ChatClient.from_config(cfg), cfg),
                    history=InteractionHistory(history) if history else None,
                )
            )
        decisions: list[_Decision] = []
        round_walls: list[float] = []
        started = time.perf_counter()
        try:
            for rnd in range(rounds):
                requests = [(me, _request(me, _observation(me, team, 0, rnd), registry))
                            for me in team]  # fmt: skip
                round_started = time.perf_counter()
                if serial:
                    for me, req in requests:
                        decisions.append(await _decide(me, req))
                else:
                    decisions += await asyncio.gather(*(_decide(me, r) for me, r in requests))
                round_walls.append(time.perf_counter() - round_started)
                for me in team:
                    me.pos = _towards(me.pos, LANDMARKS[me.target])
                    me.seq += 1
        finally:
            for me in team:
                await me.selector.aclose()
        wall = time.perf_counter() - started
        threads_used = server.threads
    ok = [d for d in decisions if d.error is None]
    warm = [d for d in ok if d.round > 0]

    def per(ds: list[_Decision], what: str) -> float:
        values = [d.prompt - d.cached if what == "uncached" else d.cached for d in ds]
        return round(statistics.mean(values), 1) if values else math.nan

    lat = [d.latency_s for d in ok]
    return {
        "bench": "llm_latency",
        "shape": f"{uavs} UAVs x {rounds} rounds, {'serial' if serial else 'concurrent'}",
        "model": server.model,
        "slots": slots,
        "history_rounds": history,
        "threads": threads_used,
        "cpu_count": os.cpu_count(),
        "loadavg_1m_before": round(load_before[0], 2),
        "loadavg_1m_after": round(os.getloadavg()[0], 2),
        "decisions": len(decisions),
        "errors": len(decisions) - len(ok),
        "latency_p50_s": round(statistics.median(lat), 3) if lat else math.nan,
        "latency_p95_s": round(percentile(lat, 95), 3) if lat else math.nan,
        "round_wall_p50_s": round(statistics.median(round_walls), 3),
        "prompt_tokens_mean": round(statistics.mean(d.prompt for d in ok), 1) if ok else math.nan,
        "uncached_per_decision": per(ok, "uncached"),
        "cached_per_decision": per(ok, "cached"),
        "uncached_per_decision_after_round0": per(warm, "uncached"),
        "wall_s": round(wall, 2),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--uavs", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=24)
    parser.add_argument("--history", type=int, default=8, help="history block in rounds (0: off)")
    parser.add_argument("--no-slots", action="store_true", help="do not pin UAVs to slots")
    parser.add_argument("--serial", action="store_true", help="one decision at a time")
    parser.add_argument("--threads", type=int, default=None, help="default: core count")
    args = parser.parse_args(argv)
    if args.uavs < 1 or args.rounds < 1 or not 0 <= args.history <= 64:
        print("llm_latency: --uavs and --rounds must be >= 1, --history 0..64", file=sys.stderr)
        return 2
    try:
        report = asyncio.run(
            run(args.uavs, args.rounds, args.history, not args.no_slots, args.serial, args.threads)
        )
    except EmbeddedUnavailable as exc:
        print(f"embedded model unavailable: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
