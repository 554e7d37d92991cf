"""Experience-memory benchmark: retrieval latency and fill rate as the memory grows.

``python -m aeroweaver_lab.bench.memory --records N`` fills a temporary on-disk memory
with N synthetic coverage records in one (task, role) through the public API (append,
a reward per round, finalise per trajectory: the daemon's write path; one transaction per
episode, or per write with ``--per-write``), reopens it as a restarted daemon would, and
times ``advantages`` for fresh states. Prints one JSON line. ``fill_s`` and
``inserts_per_s`` count the time inside the memory's API only, not the generation of the
synthetic states (before 2026-12-03 they did, and every write was its own transaction).

``--writer backlog`` fills through the other write path instead: peers' finalised records
as a late joiner fetches them (``ExperienceMemory.store_peers``, one transaction per wire
batch of ``MAX_BATCH_RECORDS``), the path where bulk speed matters; a daemon's own writes
come one decision per round. The per-sender caps are raised to hold every record, so no
eviction runs.

The states imitate a searcher's view of the coverage task (own pose, landmarks and peers
within sensing range with offsets and distances, peer messages, round), so token sets,
vocabulary size and posting-list lengths are realistic, not best case.
"""

from __future__ import annotations

import contextlib
import json
import math
import random
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from aeroweaver_edge.agent.memory.experience import ExperienceMemory
from aeroweaver_edge.agent.memory.records import Neighbour
from aeroweaver_edge.cli.errors import ArgumentParser
from aeroweaver_edge.contracts.defaults import MAX_ROUNDS, SENSING_RADIUS_M
from aeroweaver_edge.contracts.wire import MAX_BATCH_RECORDS, ExperienceRecord, Header

TASK = "coverage"
ROLE = "searcher"
UAVS = ("uav1", "uav2", "uav3")
ROUNDS = MAX_ROUNDS
LANDMARKS = {"L1": (-28.0, 24.0), "L2": (4.0, 34.0), "L3": (32.0, 20.0)}
SENSING_M = SENSING_RADIUS_M
WRITERS = ("own", "backlog")


def _state(rng: random.Random, uav: str, rnd: int) -> tuple[str, list[str]]:
    """A coverage-like state description and the invocations callable in it."""
    n, e = rng.uniform(-70, 70), rng.uniform(-70, 70)
    vn, ve = rng.uniform(-11, 11), rng.uniform(-11, 11)
    lines = [
        f"task coverage; role searcher; self {uav}; round {rnd}/{ROUNDS}",
        f"own pos ({n:.1f}, {e:.1f}) vel ({vn:.1f}, {ve:.1f})",
    ]
    options = ["hold_position()", "explore_local()"]
    for name, (ln, le) in LANDMARKS.items():
        d = math.hypot(ln - n, le - e)
        if d <= SENSING_M:
            lines.append(f"landmark {name} at ({ln - n:+.1f}, {le - e:+.1f}) dist {d:.1f} m")
            options.append(f"cover_landmark(target={name})")
    for peer in UAVS:
        if peer != uav and rng.random() < 0.6:
            pn, pe = rng.uniform(-45, 45), rng.uniform(-45, 45)
            lines.append(f"peer {peer} at ({pn:+.1f}, {pe:+.1f}) dist {math.hypot(pn, pe):.1f} m")
            options.append(f"send_status(to={peer})")
            if rng.random() < 0.5:
                lines.append(f"msg from {peer}: status covering {rng.choice(list(LANDMARKS))}")
    uncovered = [k for k in LANDMARKS if rng.random() < 0.5]
    lines.append("uncovered: " + (" ".join(uncovered) if uncovered else "none"))
    return "\n".join(lines), options


def _reward(rng: random.Random, invocation: str) -> float:
    base = {"cover_landmark": -0.4, "explore_local": -0.8, "hold_position": -1.0}
    return base.get(invocation.split("(")[0], -0.9) + rng.gauss(0.0, 0.3)


def fill(
    memory: ExperienceMemory, records: int, rng: random.Random, *, per_write: bool = False
) -> float:
    """Append ``records`` decisions, reward each round and finalise each trajectory, one
    episode (3 UAVs x 24 rounds) at a time. Returns the seconds spent inside the memory's
    API: each episode's synthetic states are generated before its writes, untimed.

    By default an episode's writes share one transaction (``ExperienceMemory.batch``, how
    bulk intake writes); ``per_write`` commits each write on its own, as a daemon does for
    the decision it must not lose."""
    done = 0
    episode = 0
    spent = 0.0
    while done < records:
        episode += 1
        plan: list[tuple[str, int, str, str, float]] = []
        for uav in UAVS:
            for rnd in range(ROUNDS):
                if done + len(plan) >= records:
                    break
                text, options = _state(rng, uav, rnd)
                inv = rng.choice(options)
                plan.append((uav, rnd, text, inv, _reward(rng, inv)))
        t0 = time.perf_counter()
        with contextlib.nullcontext() if per_write else memory.batch():
            for i, (uav, rnd, text, inv, reward) in enumerate(plan):
                memory.append(
                    task=TASK,
                    role=ROLE,
                    uav=uav,
                    episode=episode,
                    round=rnd,
                    state_text=text,
                    skill=inv.split("(")[0],
                    invocation=inv,
                )
                memory.add_reward(uav, episode, rnd, reward, "bench")
                if i + 1 == len(plan) or plan[i + 1][0] != uav:
                    memory.finalise(uav, episode)
        spent += time.perf_counter() - t0
        done += len(plan)
    return spent


def fill_backlog(memory: ExperienceMemory, records: int, rng: random.Random) -> float:
    """Store ``records`` peers' finalised records (3 peers x 24 rounds per episode) the
    way a late joiner stores a fetched backlog: one ``store_peers`` per wire batch. Returns
    the seconds spent inside the memory's API (the records are built untimed)."""
    memory.max_records_per_sender = records + 1
    memory.max_bytes_per_sender = records * 8192
    done = 0
    episode = 0
    spent = 0.0
    while done < records:
        episode += 1
        batch: list[tuple[ExperienceRecord, bool]] = []
        for i, uav in enumerate(UAVS):
            ret = 0.0
            rows: list[tuple[int, str, str, float]] = []
            for rnd in range(ROUNDS):
                if done + len(batch) + len(rows) >= records:
                    break
                text, options = _state(rng, uav, rnd)
                inv = rng.choice(options)
                rows.append((rnd, text, inv, _reward(rng, inv)))
            for rnd, text, inv, reward in reversed(rows):  # G_t = r_t + gamma G_t+1
                ret = reward + memory.gamma * ret
                h = Header(sender=uav, epoch=1, seq=episode * 100 + rnd, stamp=0.0)
                record = ExperienceRecord(
                    h=h, task=TASK, role=ROLE, uav=uav, episode=episode, round=rnd,
                    state_text=text, skill=inv.split("(")[0], invocation=inv,
                    reward=reward, ret=ret, final=True, run=f"peer-run-{i}",
                )  # fmt: skip
                batch.append((record, True))
        t0 = time.perf_counter()
        for start in range(0, len(batch), MAX_BATCH_RECORDS):
            memory.store_peers(batch[start : start + MAX_BATCH_RECORDS])
        spent += time.perf_counter() - t0
        done += len(batch)
    return spent


def _identity(n: Neighbour) -> tuple[object, ...]:
    return (n.run, n.key, n.seq, n.similarity)  # the value may be NaN (in flight)


def _transactions(writer: str, per_write: bool) -> str:
    if writer == "backlog":
        return f"per {MAX_BATCH_RECORDS} records"
    return "per write" if per_write else "per episode"


def _percentile(values: Sequence[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


def run(
    records: int,
    queries: int = 200,
    seed: int = 0,
    *,
    per_write: bool = False,
    writer: str = "own",
    check_whole: bool = False,
) -> dict[str, Any]:
    """Fill, reopen and query a temporary memory; figures in ms, s and bytes."""
    if records < 1 or queries < 1:
        raise ValueError("records and queries must be at least 1")
    if writer not in WRITERS:
        raise ValueError(f"writer must be one of {', '.join(WRITERS)}")
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory(prefix="aw-bench-memory-") as tmp:
        path = Path(tmp) / "memory.sqlite"
        with ExperienceMemory(path) as memory:
            if writer == "backlog":
                fill_s = fill_backlog(memory, records, rng)
            else:
                fill_s = fill(memory, records, rng, per_write=per_write)
        db_bytes = sum(p.stat().st_size for p in Path(tmp).iterdir())

        t0 = time.perf_counter()
        with ExperienceMemory(path) as memory:
            opened_s = time.perf_counter() - t0
            probe, probe_opts = _state(rng, "uav1", 0)
            t0 = time.perf_counter()
            memory.advantages(TASK, ROLE, probe, probe_opts)  # builds the index
            index_s = time.perf_counter() - t0
            latencies, whole, same = [], [], 0
            for q in range(queries):
                text, options = _state(rng, UAVS[q % len(UAVS)], q % ROUNDS)
                t0 = time.perf_counter()
                memory.advantages(TASK, ROLE, text, options)
                latencies.append((time.perf_counter() - t0) * 1e3)
                if check_whole:
                    t0 = time.perf_counter()
                    reference = memory.whole_group_neighbourhood(TASK, ROLE, text)
                    whole.append((time.perf_counter() - t0) * 1e3)
                    got = memory.neighbourhood_of(TASK, ROLE, text)
                    same += [_identity(n) for n in got] == [_identity(n) for n in reference]
    return {
        "records": records,
        "queries": queries,
        "p50_ms": round(statistics.median(latencies), 3),
        "p99_ms": round(_percentile(latencies, 0.99), 3),
        "max_ms": round(max(latencies), 3),
        "fill_s": round(fill_s, 3),
        "inserts_per_s": round(records / fill_s, 1),
        "writer": writer,
        "transactions": _transactions(writer, per_write),
        **(
            {
                "whole_group_p50_ms": round(statistics.median(whole), 3),
                "same_neighbourhood": f"{same} of {queries}",
            }
            if check_whole
            else {}
        ),
        "open_s": round(opened_s, 3),
        "index_build_s": round(index_s, 3),
        "db_bytes": db_bytes,
    }


def main(argv: Sequence[str] | None = None, *, prog: str = "aeroweaver bench memory") -> int:
    parser = ArgumentParser(prog=prog, description="Experience-memory retrieval benchmark.")
    parser.add_argument("--records", type=int, default=10_000, help="records in one role")
    parser.add_argument("--queries", type=int, default=200, help="timed retrievals")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--per-write",
        action="store_true",
        help="commit every write on its own (a daemon's decisions) instead of per episode",
    )
    parser.add_argument(
        "--writer",
        choices=WRITERS,
        default="own",
        help="own: a daemon's decisions, rewards and finalise; backlog: peers' finalised "
        "records stored as a late joiner stores a fetch",
    )
    parser.add_argument(
        "--check-whole",
        action="store_true",
        help="also time the whole-group selection per query and count identical "
        "neighbourhoods (what the indexed, early-stopping selection must equal)",
    )
    args = parser.parse_args(argv)
    if args.per_write and args.writer != "own":
        print("bench memory: --per-write applies to --writer own only", file=sys.stderr)
        return 2
    if args.records < 1 or args.queries < 1:
        print("bench memory: --records and --queries must be at least 1", file=sys.stderr)
        return 2
    figures = run(
        args.records,
        args.queries,
        args.seed,
        per_write=args.per_write,
        writer=args.writer,
        check_whole=args.check_whole,
    )
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
