"""``aeroweaver``: run a daemon, a simulated swarm, a probe or a benchmark."""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import signal
import sys
from collections.abc import Coroutine, Sequence
from pathlib import Path
from typing import Any, TypeVar

from aeroweaver_edge.config import ConfigError, LLMConfig, UavConfig, load_config

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

    opts = SwarmOptions(
        task=args.task,
        uavs=args.uavs,
        seed=args.seed,
        episodes=args.episodes,
        max_rounds=args.rounds,
        processes=args.processes,
        selector=args.selector,
        llm=_llm_from_args(args),
        beta=args.beta,
        memory_dir=Path(args.memory_dir) if args.memory_dir else None,
        deadline_s=args.deadline,
    )
    view = None if args.quiet else LiveView()
    summary = _run(run_swarm(opts, on_round=view.on_round if view else None))
    data = summary.as_dict()
    print_summary(data)
    if args.json:
        write_json(summary, Path(args.json))
        print(f"summary written to {args.json}")
    return 0


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
    raise SystemExit(f"unknown benchmark {args.what!r}")


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
    s.add_argument("--uavs", type=int, default=3)
    s.add_argument("--seed", type=int, default=1)
    s.add_argument("--episodes", type=int, default=1)
    s.add_argument("--rounds", type=int, default=24, help="horizon in rounds")
    s.add_argument("--processes", action="store_true", help="one OS process per daemon")
    s.add_argument("--selector", choices=["llm", "scripted"], default="llm")
    s.add_argument(
        "--beta", type=float, default=0.8, help="experience correction weight (0: plain)"
    )
    s.add_argument("--memory-dir", help="keep experience memory here (persists across runs)")
    s.add_argument("--deadline", type=float, default=30.0, help="seconds a round may take")
    s.add_argument("--json", metavar="PATH", help="write the run summary as JSON")
    s.add_argument("--quiet", action="store_true", help="no per-round view")
    _add_llm_flags(s)
    s.set_defaults(func=cmd_sim)

    d = sub.add_parser("daemon", help="run one UAV daemon")
    d.add_argument("--config", required=True, help="uav.toml (or .json)")
    d.set_defaults(func=cmd_daemon)

    pr = sub.add_parser("probe", help="classify an endpoint's logprob support")
    _add_llm_flags(pr)
    pr.set_defaults(func=cmd_probe)

    b = sub.add_parser("bench", help="benchmarks that print figures")
    b.add_argument("what", choices=["memory"])
    b.add_argument("--records", type=int, default=10_000)
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
    except KeyboardInterrupt:
        return 130
    except asyncio.CancelledError:
        return 130


if __name__ == "__main__":
    sys.exit(main())
