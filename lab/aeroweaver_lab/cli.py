"""The lab's commands for the ``aeroweaver`` program (entry points ``aeroweaver.commands``):

* ``aeroweaver bench NAME ...``: the benchmark runner (``bench run``, also ``bench`` with only
  runner flags), the benchmarks with parsers of their own (``adaptation``, ``memory``) and
  the rest (``scale``, ``flood``, ``fuzz``, ...) on the common flags below;
* ``aeroweaver central ...``: a baseline's central node as its own process.

Errors follow the runtime's rule: one line and exit 2 for a user's mistake (``cli.errors``).
"""

from __future__ import annotations

import argparse
import asyncio
import importlib
import logging
import sys
from collections.abc import Sequence

from aeroweaver_edge.cli.checks import finite, int_in
from aeroweaver_edge.cli.errors import ArgumentParser, report
from aeroweaver_edge.config import MAX_UAVS
from aeroweaver_edge.contracts import defaults
from aeroweaver_edge.runtime import log_setup
from aeroweaver_edge.runtime.plugins import Command
from aeroweaver_edge.tasks import TASK_NAMES, canonical_task

BENCH_WHATS = [
    "run",
    "adaptation",
    "memory",
    "memory-kill",
    "kill-restart",
    "scale",
    "reference",
    "mavlink",
    "llm_latency",
    "weights",
    "security",
    "flood",
    "fuzz",
]

# Benchmarks whose every flag is their own: ``aeroweaver bench NAME ...`` is their main.
OWN_PARSER_BENCHES = ("adaptation", "memory")

STOPPED = "aeroweaver: bench stopped; rerun the same command to resume"


def _runner_args(argv: Sequence[str]) -> list[str] | None:
    """``run ...``, or no benchmark name at all (``bench --quick``, ``bench --tasks
    coverage``): the runner's own arguments, else None. The runner has its own parser (its
    --seeds, --tasks, --rounds mean other things)."""
    args = list(argv)
    if args[:1] == ["run"]:
        return args[1:]
    help_only = bool(args) and all(a in ("-h", "--help") for a in args)
    if not help_only and not set(args) & set(BENCH_WHATS):
        return args
    return None


def bench_main(argv: Sequence[str], verbose: bool) -> int:
    """``aeroweaver [-v] bench ...``."""
    args = list(argv)
    while args[:1] in (["-v"], ["--verbose"]):
        verbose, args = True, args[1:]
    own = args[0] if args else None
    runner_args = None if own in OWN_PARSER_BENCHES else _runner_args(args)
    if own in OWN_PARSER_BENCHES or runner_args is not None:
        logging.basicConfig(
            level=logging.DEBUG if verbose else logging.WARNING,
            format="%(asctime)s %(levelname)s %(name)s: %(message)s",
            stream=sys.stderr,
        )
        try:
            if runner_args is not None:
                from aeroweaver_lab.bench import runner

                return runner.main(runner_args)
            bench = importlib.import_module(f"aeroweaver_lab.bench.{own}")
            return int(bench.main(args[1:], prog=f"aeroweaver bench {own}"))
        except (KeyboardInterrupt, asyncio.CancelledError):
            print(STOPPED, file=sys.stderr)
            return 130
        except Exception as exc:
            return report(exc, verbose=verbose)
    parsed = build_bench_parser().parse_args(args)
    verbose = verbose or parsed.verbose
    log_setup.setup("bench", verbose=verbose, log_level=parsed.log_level)
    try:
        return cmd_bench(parsed)
    except KeyboardInterrupt:
        return 130
    except Exception as exc:
        return report(exc, verbose=verbose)


def cmd_bench(args: argparse.Namespace) -> int:
    if args.what == "memory-kill":
        from aeroweaver_lab.bench import memory_kill

        return memory_kill.main(["--kills", str(args.kills)])
    if args.what == "kill-restart":
        from aeroweaver_lab.bench import kill_restart

        return kill_restart.main(["--cycles", str(args.kills)])
    if args.what == "reference":
        from aeroweaver_lab.bench import reference

        argv = ["--seeds", *map(str, args.seeds)]
        if args.tasks:
            argv += ["--tasks", *args.tasks]
        return reference.main(argv)
    if args.what == "scale":
        from aeroweaver_lab.bench import scale

        argv = ["--sizes", *map(str, args.sizes or [3, 10, 25, 50]), "--rounds", str(args.rounds)]
        argv += ["--seed", str(args.seed), "--task", args.task]
        if args.in_process:
            argv.append("--in-process")
        return scale.main(argv)
    if args.what == "mavlink":  # flight link: setpoint rate and command round trip
        from aeroweaver_lab.bench import mavlink

        return mavlink.main(["--seconds", str(args.seconds)])
    if args.what == "security":  # TLS / ACL / signature overhead, per message and per round
        from aeroweaver_lab.bench import security

        argv = ["--runs", *map(str, args.sizes or [3, 10]), "--rounds", str(args.rounds)]
        return security.main([*argv, "--seed", str(args.seed), "--task", args.task])
    if args.what == "flood":  # a compromised enrolled UAV floods a secured swarm (issue 22)
        from aeroweaver_lab.bench import flood

        argv = ["--uavs", str(args.uavs), "--rounds", str(args.rounds), "--seed", str(args.seed)]
        return flood.main([*argv, "--task", args.task])
    if args.what == "fuzz":  # hostile payloads over every key
        from aeroweaver_lab.bench import fuzz_wire

        argv = ["--cases", str(args.cases), "--seed", str(args.seed)]
        return fuzz_wire.main([*argv, *(["--insecure"] if args.insecure else [])])
    if args.what == "llm_latency":
        from aeroweaver_lab.bench import llm_latency

        return llm_latency.main(["--uavs", str(args.uavs), "--rounds", str(args.rounds)])
    if args.what == "weights":  # the embedded model's weight formats: prompt tokens/s
        from aeroweaver_lab.bench import weights

        return weights.main([])
    raise AssertionError(f"unknown benchmark {args.what!r}")  # argparse choices


def build_bench_parser() -> argparse.ArgumentParser:
    b = ArgumentParser(prog="aeroweaver bench", description="Benchmarks that print figures.")
    b.add_argument(
        "what",
        choices=BENCH_WHATS,
        help="run: the benchmark (tasks x conditions x seeds; 'aeroweaver bench run --help'); "
        "with no name and any runner flags, 'aeroweaver bench [--quick] ...' is 'bench run'. "
        "run, adaptation and memory take flags of their own ('aeroweaver bench NAME --help')",
    )
    b.add_argument(
        "--kills", type=int_in(1), default=200, help="memory-kill, kill-restart: SIGKILLs"
    )
    b.add_argument(
        "--sizes",
        type=int_in(1, MAX_UAVS),
        nargs="+",
        default=None,
        help="scale, security: swarm sizes (default 3 10 25 50; security: 3 10)",
    )
    b.add_argument(
        "--task",
        type=canonical_task,
        choices=TASK_NAMES,
        default="coverage",
        help="scale, security: task",
    )
    b.add_argument(
        "--rounds",
        type=int_in(1),
        default=defaults.MAX_ROUNDS,
        help="scale, llm_latency, security: rounds per run",
    )
    b.add_argument("--seed", type=int, default=1, help="scale: layout seed")
    b.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5], help="reference: seeds")
    b.add_argument(
        "--tasks", nargs="+", type=canonical_task, choices=TASK_NAMES, help="reference: tasks (all)"
    )
    b.add_argument(
        "--in-process", action="store_true", help="scale: daemons in one process (no RSS)"
    )
    b.add_argument("--seconds", type=finite(), default=5.0, help="mavlink: streaming time")
    b.add_argument("--uavs", type=int, default=3, help="llm_latency, flood: UAVs")
    b.add_argument("--cases", type=int_in(1), default=100_000, help="fuzz: payloads")
    b.add_argument("--insecure", action="store_true", help="fuzz: no signature layer")
    _add_log_flags(b)
    return b


def _add_log_flags(p: argparse.ArgumentParser) -> None:
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging (tracebacks)")
    p.add_argument(
        "--log-level", type=str.upper, choices=log_setup.LEVELS, metavar="LEVEL", default=None,
        help="DEBUG, INFO, WARNING, ERROR or CRITICAL (default WARNING; -v is DEBUG)",
    )  # fmt: skip


def central_main(argv: Sequence[str], verbose: bool) -> int:
    """``aeroweaver [-v] central ...``."""
    from aeroweaver_lab.baselines.cli import build_parser, cmd_central

    parsed = build_parser().parse_args(list(argv))
    verbose = verbose or parsed.verbose
    log_setup.setup("central", verbose=verbose, log_level=parsed.log_level)
    try:
        return cmd_central(parsed)
    except KeyboardInterrupt:
        return 130
    except Exception as exc:
        return report(exc, verbose=verbose)


bench = Command("benchmarks that print figures (the aeroweaver-lab distribution)", bench_main)
central = Command("run a baseline's central node (centralized / hmas2) on the mesh", central_main)

__all__ = ["BENCH_WHATS", "bench", "bench_main", "build_bench_parser", "central", "central_main"]
