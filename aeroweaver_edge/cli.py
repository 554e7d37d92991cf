"""``aeroweaver``: run a daemon, a simulated swarm, a probe or a benchmark."""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import signal
import sys
from collections.abc import Coroutine, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar

from aeroweaver_edge.config import ConfigError, LLMConfig, UavConfig, load_config
from commander.mission_parser import MissionParseError

T = TypeVar("T")


def _llm_from_args(args: argparse.Namespace) -> LLMConfig:
    url = args.llm or os.environ.get("AEROWEAVER_LLM_URL")
    model = args.model or os.environ.get("AEROWEAVER_LLM_MODEL")
    fields: dict[str, Any] = {"base_url": url}
    if model:
        fields["model"] = model
    if args.api_key_env:
        fields["api_key_env"] = args.api_key_env
    if args.llm_deadline is not None:
        fields["deadline_s"] = args.llm_deadline
    return LLMConfig(**fields)


def _run(coro: Coroutine[Any, Any, T]) -> T:
    """Run a coroutine; SIGTERM cancels it like Ctrl-C so every session is closed."""

    async def main() -> T:
        task = asyncio.current_task()
        loop = asyncio.get_running_loop()
        if task is not None:
            for sig in (signal.SIGTERM, signal.SIGINT):
                loop.add_signal_handler(sig, task.cancel)
        return await coro

    return asyncio.run(main())


def cmd_sim(args: argparse.Namespace) -> int:
    from aeroweaver_edge.sim.swarm import SwarmOptions, run_swarm, write_json
    from aeroweaver_edge.sim.view import LiveView, print_summary

    task, uavs = args.task, args.uavs or 3
    if args.mission:
        task, uavs = _sim_shape(args.mission, args.uavs)
    opts = SwarmOptions(
        task=task,
        uavs=uavs,
        mission_text=args.mission,
        top_k=args.top_k,
        seed=args.seed,
        episodes=args.episodes,
        max_rounds=args.rounds,
        processes=args.processes,
        selector=args.selector,
        llm=_llm_from_args(args),
        beta=args.beta,
        memory_dir=Path(args.memory_dir) if args.memory_dir else None,
        deadline_s=args.deadline,
        history_rounds=args.history,
        state_context=args.state_text == "full",
        slots=True if args.llm_slots else None,
    )
    view = None if args.quiet else LiveView()
    try:
        summary = _run(run_swarm(opts, on_round=view.on_round if view else None))
    except (KeyboardInterrupt, asyncio.CancelledError):
        print("aeroweaver: stopped by the operator; every UAV was told to hold", file=sys.stderr)
        return 130
    data = summary.as_dict()
    print_summary(data)
    if args.json:
        write_json(summary, Path(args.json))
        print(f"summary written to {args.json}")
    return 0


def _sim_shape(text: str, uavs: int | None) -> tuple[str, int]:
    """Task and team size a mission asks for, so the simulator can spawn that swarm; the
    Commander then parses the mission again, properly, against the live roster."""
    from aeroweaver_edge.sim.tasks import TASKS
    from commander.mission_parser import parse_fallback

    record = parse_fallback(text, [f"uav{i}" for i in range(uavs or 10)])
    if record.task not in TASKS:
        raise SystemExit(
            f"aeroweaver: the mission reads as a {record.task} mission; the simulator runs only "
            f"{', '.join(sorted(TASKS))} so far"
        )
    return record.task, uavs or len(record.uavs)


def cmd_daemon(args: argparse.Namespace) -> int:
    from aeroweaver_edge.app import run_daemon

    cfg = load_config(args.config, UavConfig)
    stats = _run(run_daemon(cfg))
    logging.getLogger("aeroweaver").info(
        "%s: %d rounds, %d holds, %d messages sent",
        cfg.uav,
        stats.rounds,
        stats.holds,
        stats.messages_sent,
    )
    return 0


def cmd_mission(args: argparse.Namespace) -> int:
    import json

    from aeroweaver_edge.config import MeshConfig
    from aeroweaver_edge.sim.view import LiveView, print_mission
    from commander.mission_start import MissionStartOptions, start_mission

    mesh = MeshConfig(
        listen=args.listen or ["tcp/127.0.0.1:0"], connect=args.connect or [],
        namespace=args.namespace,
    )  # fmt: skip
    llm = None if args.no_llm else _llm_from_args(args)
    opts = MissionStartOptions(
        text=args.text, swarm=args.swarm, mesh=mesh, llm=llm, roster_wait_s=args.roster_wait,
        top_k=args.top_k,
        sim_world=args.sim_world, seed=args.seed, episodes=args.episodes,
        max_rounds=args.rounds,
    )  # fmt: skip

    async def go() -> dict[str, Any]:
        if llm is not None and llm.base_url is None:
            from aeroweaver_edge.llm.embedded import EmbeddedServer

            async with EmbeddedServer() as server:
                local = llm.model_copy(update={"base_url": server.base_url, "model": server.model})
                return await start_mission(replace(opts, llm=local), LiveView().on_round)
        return await start_mission(opts, LiveView().on_round)

    out = _run(go())
    from rich.console import Console

    print_mission(out["mission"], Console())
    print(f"mission ended: {out['ended']}; wall {out['wall_s']:.1f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2, default=str) + "\n", encoding="utf-8")
        print(f"mission record written to {args.json}")
    return 0


def cmd_probe(args: argparse.Namespace) -> int:
    from aeroweaver_edge.sim.swarm import SwarmOptions, _probe, _shared_llm

    async def go() -> str:
        async with _shared_llm(SwarmOptions(llm=_llm_from_args(args))) as (llm, _source):
            return f"{llm.base_url} {llm.model}: {await _probe(llm)}"

    print(_run(go()))
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    if args.what == "memory":
        from aeroweaver_edge.bench import memory

        return memory.main(["--records", str(args.records)])
    if args.what == "llm_latency":
        from aeroweaver_edge.bench import llm_latency

        return llm_latency.main(["--uavs", str(args.uavs), "--rounds", str(args.rounds)])
    raise SystemExit(f"unknown benchmark {args.what!r}")


def _history_rounds(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of rounds") from None
    if not 0 <= value <= 64:
        raise argparse.ArgumentTypeError(f"{value} is outside 0..64")
    return value


def _add_llm_flags(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--llm", metavar="URL", help="OpenAI-compatible base URL (default: embedded SmolLM2)"
    )
    p.add_argument("--model", help="model name at that endpoint")
    p.add_argument("--api-key-env", help="name of the environment variable holding the API key")
    p.add_argument("--llm-deadline", type=float, help="seconds per LLM decision (default 20)")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="aeroweaver", description=__doc__)
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("sim", help="fly a simulated swarm mission (world + daemons + Commander)")
    s.add_argument("task", nargs="?", default="coverage")
    s.add_argument("--mission", help='natural-language mission, e.g. "Cover the three landmarks"')
    s.add_argument(
        "--uavs", type=int, default=None, help="swarm size (default 3, or the mission's)"
    )
    s.add_argument("--seed", type=int, default=1)
    s.add_argument("--episodes", type=int, default=1)
    s.add_argument("--rounds", type=int, default=24, help="horizon in rounds")
    s.add_argument("--processes", action="store_true", help="one OS process per daemon")
    s.add_argument("--selector", choices=["llm", "scripted"], default="llm")
    s.add_argument(
        "--beta", type=float, default=0.8, help="experience correction weight (0: plain)"
    )
    s.add_argument("--top-k", type=int, default=8, help="task skills per UAV (with --mission)")
    s.add_argument(
        "--history", type=_history_rounds, default=8, metavar="ROUNDS",
        help="interaction history in each agent's context, in blocks of ROUNDS (0: none)",
    )  # fmt: skip
    s.add_argument(
        "--state-text", choices=["full", "observation"], default="full",
        help="retrieval state: with peer messages and mission context (full) or without",
    )  # fmt: skip
    s.add_argument(
        "--llm-slots", action="store_true",
        help="pin UAV i to cache slot i of a llama-server --llm endpoint (id_slot; the "
        "embedded server always does); the server needs one slot per UAV (-np)",
    )  # fmt: skip
    s.add_argument("--memory-dir", help="keep experience memory here (persists across runs)")
    s.add_argument("--deadline", type=float, default=30.0, help="seconds a round may take")
    s.add_argument("--json", metavar="PATH", help="write the run summary as JSON")
    s.add_argument("--quiet", action="store_true", help="no per-round view")
    _add_llm_flags(s)
    s.set_defaults(func=cmd_sim)

    d = sub.add_parser("daemon", help="run one UAV daemon")
    d.add_argument("--config", required=True, help="uav.toml (or .json)")
    d.set_defaults(func=cmd_daemon)

    m = sub.add_parser("mission", help="plan and run a mission on the daemons that are up")
    msub = m.add_subparsers(dest="mission_command", required=True)
    ms = msub.add_parser("start", help="parse, assign, publish and watch a mission")
    ms.add_argument("text", help="the mission in natural language")
    ms.add_argument("--swarm", default="default")
    ms.add_argument("--connect", action="append", help="zenoh endpoint of a daemon or router")
    ms.add_argument("--listen", action="append", help="zenoh endpoint to listen on")
    ms.add_argument("--namespace", help="zenoh namespace of the swarm")
    ms.add_argument("--roster-wait", type=float, default=3.0, help="seconds to discover daemons")
    ms.add_argument("--sim-world", action="store_true", help="also run the kinematic world")
    ms.add_argument("--seed", type=int, default=1)
    ms.add_argument("--episodes", type=int, default=1)
    ms.add_argument("--rounds", type=int, default=24)
    ms.add_argument("--no-llm", action="store_true", help="rule-based parsing and roles only")
    ms.add_argument("--top-k", type=int, default=8, help="task skills activated per UAV")
    ms.add_argument("--json", metavar="PATH", help="write task record, assignments, outcome")
    _add_llm_flags(ms)
    ms.set_defaults(func=cmd_mission)

    pr = sub.add_parser("probe", help="classify an endpoint's logprob support")
    _add_llm_flags(pr)
    pr.set_defaults(func=cmd_probe)

    b = sub.add_parser("bench", help="benchmarks that print figures")
    b.add_argument("what", choices=["memory", "llm_latency"])
    b.add_argument("--records", type=int, default=10_000, help="memory: records to fill")
    b.add_argument("--uavs", type=int, default=3, help="llm_latency: UAVs sharing the server")
    b.add_argument("--rounds", type=int, default=24, help="llm_latency: rounds")
    b.set_defaults(func=cmd_bench)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.WARNING,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        return int(args.func(args))
    except ConfigError as exc:
        print(f"aeroweaver: config error: {exc}", file=sys.stderr)
        return 2
    except MissionParseError as exc:
        print(f"aeroweaver: cannot understand the mission: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except asyncio.CancelledError:
        return 130


if __name__ == "__main__":
    sys.exit(main())
