"""Micro-benchmark of the kinematic world and a task's rewards (coverage, 3 UAVs by default).

``python -m aeroweaver_lab.bench.world_speed`` prints one JSON line. Each figure is the
median over batches of the per-call time in microseconds, so one slow batch (GC, a noisy
neighbour) does not skew it. Speed goals live here, not in timed tests (DESIGN §11).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np

from aeroweaver_edge.tasks import create


def per_call_us(fn: Callable[[], object], calls: int, batches: int) -> float:
    samples = []
    for _ in range(batches):
        t0 = time.perf_counter_ns()
        for _ in range(calls):
            fn()
        samples.append((time.perf_counter_ns() - t0) / calls / 1e3)
    return round(statistics.median(samples), 3)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--calls", type=int, default=2000, help="calls per batch")
    parser.add_argument("--batches", type=int, default=7)
    parser.add_argument("--uavs", type=int, default=3)
    parser.add_argument("--task", default="coverage")
    args = parser.parse_args(argv)

    task = create(args.task, args.uavs)
    world = task.build_world(np.random.default_rng(66001))
    for i, uav in enumerate(world.uav_ids):
        world.set_velocity(uav, (11.0 * math.cos(i), 11.0 * math.sin(i), 0.0))

    t0 = time.perf_counter()
    task.rewards(world)  # first call: imports mpe2 and builds the scenario world
    first_reward_s = time.perf_counter() - t0

    first = world.uav_ids[0]
    result = {
        "bench": "world_speed",
        "task": args.task,
        "uavs": args.uavs,
        "world_step_us": per_call_us(world.step, args.calls, args.batches),
        "reward_eval_us": per_call_us(lambda: task.rewards(world), args.calls, args.batches),
        "complete_us": per_call_us(lambda: task.complete(world, 1), args.calls, args.batches),
        "sense_us": per_call_us(lambda: world.sense(first), args.calls, args.batches),
        "first_reward_incl_mpe2_import_s": round(first_reward_s, 4),
        "ticks_per_step": world.ticks // max(1, args.calls * args.batches),
        "python": sys.version.split()[0],
    }
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
