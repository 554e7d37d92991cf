"""Decision latency of the embedded model: ``python -m aeroweaver_edge.bench.llm_latency``.

Builds a realistic ~600-token decision prompt with ``agent.prompt`` and times the selector's
request (``max_tokens 1``, logprobs, top 20) against the embedded llama.cpp server:

* **cold** — ``cache_prompt: false``: the whole prompt is processed every time;
* **warm** — prompt cache on, static prefix shared, per-round tail different each time
  (what a daemon sees from round to round).

Prints one JSON line. Numbers are only meaningful on an idle machine (notes/llm.md).
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
from typing import Any

from aeroweaver_edge.agent.prompt import build_messages
from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.llm.embedded import EmbeddedServer, EmbeddedUnavailable
from aeroweaver_edge.observation import Observation, VehicleState
from aeroweaver_edge.ports import Candidate, DecisionRequest
from aeroweaver_edge.wire import Header, InboxMessage

_SKILLS = {
    "cover_landmark": "Fly to a visible landmark and stay over it so that it counts as "
    "covered. Take the nearest landmark no peer has claimed; peers announce claims with an "
    "intent message naming target_id. Sends an intent message to reachable peers.",
    "explore_local": "Fly a short leg in a compass direction to find landmarks outside "
    "sensing range. Use it when no unclaimed landmark is visible; prefer directions away "
    "from peers.",
    "return_in_bounds": "Turn back towards the arena centre when near the boundary (63 m "
    "from the centre); do this before anything else.",
    "hold_position": "Stay where you are. Safe default; also keeps you over a landmark you "
    "already cover.",
}


def decision_request(round_no: int) -> DecisionRequest:
    """A coverage decision; ``round_no`` changes only the per-round tail of the prompt."""
    header = Header(sender="uav2", epoch=1, seq=round_no, stamp=0.0)
    obs = Observation(
        uav="uav1",
        episode=1,
        round=round_no,
        own=VehicleState(pos=(float(round_no), -12.0, -5.0), vel=(2.0, 0.0, 0.0)),
        messages=(
            InboxMessage(
                h=header,
                to="uav1",
                round=round_no - 1,
                kind="intent",
                body={"target_id": "L3", "north": 20.0, "east": 35.0},
            ),
        ),
    )
    candidates = [
        Candidate("A", "cover_landmark", {"target_id": "L1"}, "cover_landmark(target_id=L1)"),
        Candidate("B", "cover_landmark", {"target_id": "L2"}, "cover_landmark(target_id=L2)"),
        Candidate("C", "cover_landmark", {"target_id": "L3"}, "cover_landmark(target_id=L3)"),
        Candidate("D", "explore_local", {"heading": "north"}, "explore_local(heading=north)"),
        Candidate("E", "explore_local", {"heading": "east"}, "explore_local(heading=east)"),
        Candidate("F", "explore_local", {"heading": "south"}, "explore_local(heading=south)"),
        Candidate("G", "return_in_bounds", {}, "return_in_bounds()"),
        Candidate("H", "hold_position", {}, "hold_position()"),
    ]
    observation_text = "\n".join(
        [
            f"round {round_no}; position north {round_no} m east -10 m; speed 2 m/s",
            f"landmark L1: {40 + round_no} m NE",
            "landmark L2: 25 m S",
            "landmark L3: 55 m E",
            "uav uav2 (searcher): 30 m E",
            "uav uav3 (searcher): 45 m SW",
        ]
    )
    return DecisionRequest(
        observation=obs,
        mission_text="Cover every landmark in the 140 m arena with one UAV each, fast and "
        "without collisions.",
        role="searcher",
        local_goal="Take the nearest landmark nobody has claimed and stay over it; tell "
        "reachable peers which one you take.",
        constraints=(
            "stay inside the arena (|north|, |east| < 70 m)",
            "keep at least 2 m from other UAVs",
        ),
        skill_docs=tuple(f"### {name}\n{doc}" for name, doc in _SKILLS.items()),
        observation_text=observation_text,
        candidates=candidates,
    )


def percentile(values: list[float], q: float) -> float:
    """Nearest-rank percentile (no interpolation: honest for small samples)."""
    ordered = sorted(values)
    rank = max(1, math.ceil(q / 100 * len(ordered)))
    return ordered[rank - 1]


async def _time(client: ChatClient, round_no: int, cache: bool) -> tuple[float, dict[str, Any]]:
    started = time.perf_counter()
    result = await client.chat(
        build_messages(decision_request(round_no)),
        max_tokens=1,
        temperature=0,
        logprobs=True,
        top_logprobs=20,
        cache_prompt=cache,
    )
    return time.perf_counter() - started, result.raw


async def run(runs: int, threads: int | None) -> dict[str, Any]:
    load_started = time.perf_counter()
    async with EmbeddedServer(threads=threads) as server:
        load_s = time.perf_counter() - load_started
        async with ChatClient(server.base_url, server.model, deadline_s=120) as client:
            await _time(client, 0, cache=False)  # first request pays one-off allocations
            cold = [(await _time(client, 1, cache=False))[0] for _ in range(runs)]
            await _time(client, 100, cache=True)  # prime the cache with the static prefix
            warm: list[float] = []
            cached: list[int] = []
            prompt_tokens = 0
            for i in range(runs):
                latency, raw = await _time(client, 101 + i, cache=True)
                warm.append(latency)
                usage = raw.get("usage", {})
                prompt_tokens = int(usage.get("prompt_tokens", 0))
                cached.append(int(usage.get("prompt_tokens_details", {}).get("cached_tokens", 0)))
        threads_used = server.threads
    return {
        "bench": "llm_latency",
        "model": server.model,
        "threads": threads_used,
        "cpu_count": os.cpu_count(),
        "loadavg_1m": round(os.getloadavg()[0], 2),
        "load_s": round(load_s, 3),
        "prompt_tokens": prompt_tokens,
        "runs": runs,
        "cold_p50_s": round(statistics.median(cold), 3),
        "cold_p95_s": round(percentile(cold, 95), 3),
        "warm_p50_s": round(statistics.median(warm), 3),
        "warm_p95_s": round(percentile(warm, 95), 3),
        "warm_cached_tokens_mean": round(statistics.mean(cached), 1),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--runs", type=int, default=10, help="timed requests per condition")
    parser.add_argument("--threads", type=int, default=None, help="default: core count")
    args = parser.parse_args(argv)
    try:
        report = asyncio.run(run(args.runs, args.threads))
    except EmbeddedUnavailable as exc:
        print(f"embedded model unavailable: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
