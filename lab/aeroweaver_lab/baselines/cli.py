"""``aeroweaver central``: a baseline's central node as its own process (identity
``central``), for daemons configured with ``agent.selector = "centralized"`` or ``"hmas2"``.
It has no flight authority: it only answers the UAVs' asks; each UAV executes (or holds) on
its own. Runs until SIGTERM / Ctrl-C."""

from __future__ import annotations

import argparse
import asyncio
import signal
import sys
from typing import Any

from aeroweaver_edge.cli.checks import check_api_key_env, check_llm_url, finite
from aeroweaver_edge.cli.errors import ArgumentParser
from aeroweaver_edge.config import LLMConfig, MeshConfig, parse_config
from aeroweaver_edge.runtime import log_setup


def build_parser() -> argparse.ArgumentParser:
    c = ArgumentParser(prog="aeroweaver central", description=__doc__)
    c.add_argument("--mode", choices=["centralized", "hmas2"], required=True)
    c.add_argument("--swarm", default="default")
    c.add_argument("--connect", action="append", help="zenoh endpoint of a router or peer")
    c.add_argument("--listen", action="append", help="zenoh endpoint to listen on")
    c.add_argument("--namespace", help="zenoh namespace of the swarm")
    c.add_argument(
        "--gather",
        type=finite(),
        default=3.0,
        help="seconds to wait for a round's asks after the first one",
    )
    c.add_argument("--llm", metavar="URL", required=True, help="OpenAI-compatible base URL")
    c.add_argument("--model", help="model name at that endpoint")
    c.add_argument("--api-key-env", help="environment variable holding the API key")
    c.add_argument("--llm-deadline", type=finite(), default=60.0, help="seconds per LLM call")
    c.add_argument("-v", "--verbose", action="store_true", help="debug logging (tracebacks)")
    c.add_argument(
        "--log-level", type=str.upper, choices=log_setup.LEVELS, metavar="LEVEL", default=None,
        help="DEBUG, INFO, WARNING, ERROR or CRITICAL (default WARNING; -v is DEBUG)",
    )  # fmt: skip
    return c


def cmd_central(args: argparse.Namespace) -> int:
    from aeroweaver_edge.mesh.session import build_zenoh_config
    from aeroweaver_lab.baselines.wiring import open_central

    mesh = parse_config(
        {
            "listen": args.listen or ["tcp/127.0.0.1:0"],
            "connect": args.connect or [],
            "namespace": args.namespace,
        },
        MeshConfig,
        "mesh flags",
    )
    build_zenoh_config(mesh)
    check_llm_url(args.llm)
    check_api_key_env(args.api_key_env)
    fields: dict[str, Any] = {"base_url": args.llm, "deadline_s": args.llm_deadline}
    if args.model:
        fields["model"] = args.model
    if args.api_key_env:
        fields["api_key_env"] = args.api_key_env
    llm = parse_config(fields, LLMConfig, "LLM flags")

    async def serve() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, stop.set)
        async with open_central(args.mode, mesh, args.swarm, llm, gather_s=args.gather) as node:
            print(
                f"central node ({args.mode}) up on swarm {args.swarm}", file=sys.stderr, flush=True
            )
            await stop.wait()
            totals = node.totals()
        print(
            f"central node stopped: {totals['rounds']} rounds, {totals['llm_calls']} LLM calls, "
            f"{totals['tokens']['total']} tokens",
            file=sys.stderr,
        )

    asyncio.run(serve())
    return 0


__all__ = ["build_parser", "cmd_central"]
