"""``aeroweaver``: run a daemon, a simulated swarm, a probe or a benchmark.

Every user error is one line on stderr naming the cause and the fix, exit status 2
(``cli_errors``); tracebacks only with ``-v``. Outputs, memory directories, the API-key
variable, the task and the skill tree are checked before any work starts (``cli_checks``).
"""

from __future__ import annotations

import argparse
import asyncio
import importlib.util
import logging
import os
import signal
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from aeroweaver_edge import defaults
from aeroweaver_edge.cli_checks import (
    check_api_key_env,
    check_llm_url,
    check_memory_dir,
    check_memory_path,
    check_output_file,
    check_skills,
    check_task,
    finite,
    int_in,
)
from aeroweaver_edge.cli_errors import ArgumentParser, report
from aeroweaver_edge.cli_runner import Stopped
from aeroweaver_edge.cli_runner import run_until_signal as _run
from aeroweaver_edge.config import (
    MAX_UAVS,
    LLMConfig,
    MeshConfig,
    UavConfig,
    load_config,
    parse_config,
)
from aeroweaver_edge.errors import UserError
from aeroweaver_edge.tasks import TASK_NAMES, canonical_task


def _llm_from_args(args: argparse.Namespace) -> LLMConfig:
    url = args.llm or os.environ.get("AEROWEAVER_LLM_URL")
    model = args.model or os.environ.get("AEROWEAVER_LLM_MODEL")
    check_llm_url(url, "--llm" if args.llm else "AEROWEAVER_LLM_URL")
    check_api_key_env(args.api_key_env)
    fields: dict[str, Any] = {"base_url": url}
    if model:
        fields["model"] = model
    if args.api_key_env:
        fields["api_key_env"] = args.api_key_env
    if args.llm_deadline is not None:
        fields["deadline_s"] = args.llm_deadline
    return parse_config(fields, LLMConfig, "LLM flags")


def cmd_sim(args: argparse.Namespace) -> int:
    from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm, write_json
    from aeroweaver_edge.orchestration.view import LiveView, print_summary

    task, uavs = args.task, args.uavs
    # Everything a user can get wrong is checked here, before any process or session starts
    # (a mission's own task and size are checked when it is parsed, also before any start).
    if task is not None or not args.mission:
        check_task(task or "coverage", uavs)
    if args.json:
        check_output_file(Path(args.json), "--json")
    if args.trace:
        check_output_file(Path(args.trace), "--trace")
    if args.memory_dir:
        check_memory_dir(Path(args.memory_dir))
    check_skills()
    if args.pace is not None and args.pace > 60:
        raise UserError(f"--pace {args.pace:g}: at most 60 seconds per round")
    llm = _llm_from_args(args) if args.selector == "llm" else LLMConfig()
    if args.link == "mavsdk" and importlib.util.find_spec("mavsdk") is None:
        raise UserError(
            "--link mavsdk needs the optional MAVSDK extra",
            "pip install 'aeroweaver-edge[mavsdk]', or use --link mavlink",
        )
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
        llm=llm,
        beta=args.beta,
        memory_dir=Path(args.memory_dir) if args.memory_dir else None,
        deadline_s=args.deadline,
        link=args.link,
        personality=args.personality,
        history_rounds=args.history,
        state_context=args.state_text == "full",
        trace_path=Path(args.trace) if args.trace else None,
        slots=True if args.llm_slots else None,
        secure=not args.insecure,
        pace_s=args.pace if args.pace is not None else (defaults.ROUND_S if args.console else 0.0),
        approval=args.approval,
        require_llm_answer=True,  # a run whose every decision would be a hold is refused
    )
    view = None if args.quiet else LiveView()
    if args.console:
        from aeroweaver_edge.cli_operator import require_extra

        require_extra("console")
        from aeroweaver_edge.console.server import with_console

        run = with_console(opts, args.console_host, args.console_port, view)
    else:
        run = run_swarm(opts, on_round=view.on_round if view else None)
    try:
        summary = _run(run)
    except (KeyboardInterrupt, Stopped):
        print("aeroweaver: stopped by the operator; every UAV was told to hold", file=sys.stderr)
        return 130
    data = summary.as_dict()
    print_summary(data)
    if args.json:
        write_json(summary, Path(args.json))
        print(f"summary written to {args.json}")
    return 0


def _stop_now(signum: int, _frame: object) -> None:
    raise Stopped(signum)


def cmd_daemon(args: argparse.Namespace) -> int:
    from aeroweaver_edge.run_dir import attach_to_run

    # A SIGTERM (the parent-death signal, systemctl stop) before the event loop handles
    # signals -- imports, config, sessions opening -- must still run the ``finally`` below,
    # or a run whose daemons were all still starting leaves its directory behind.
    signal.signal(signal.SIGTERM, _stop_now)
    # Started by a simulated run: die with it, and the last one out removes its directory.
    member = attach_to_run(os.environ)
    try:
        return _daemon(args)
    except Stopped as stop:  # stopped before the loop ran
        return 0 if stop.signum == signal.SIGTERM else 130
    finally:
        # The loop puts SIGTERM back to its default when it closes: ignore it while leaving.
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if member is not None:
            member.leave()


def _daemon(args: argparse.Namespace) -> int:
    from aeroweaver_edge.app import run_daemon
    from aeroweaver_edge.mesh import build_zenoh_config
    from aeroweaver_edge.systemd_notify import Supervision

    cfg = load_config(args.config, UavConfig)
    build_zenoh_config(cfg.mesh)  # a bad endpoint or namespace: a config error, now
    if cfg.agent.memory_required:
        check_memory_path(cfg.agent.memory_path)
    if cfg.agent.selector in ("llm", "hmas2"):
        check_api_key_env(cfg.llm.api_key_env)
        check_llm_url(cfg.llm.base_url, "llm.base_url")
    check_skills()
    supervision = Supervision.from_env()

    async def supervised() -> Any:
        def ready(daemon: object) -> None:
            supervision.ready(f"{cfg.uav} up: mesh open, vehicle link started")

        try:
            return await run_daemon(cfg, on_ready=ready)
        finally:
            await supervision.aclose()

    def stopping(signum: int) -> None:
        supervision.stopping(f"{cfg.uav} stopping on {signal.Signals(signum).name}: holding")

    try:
        stats = _run(supervised(), on_signal=stopping)
    except Stopped as stop:
        # systemctl stop sends SIGTERM: a clean, expected end (exit 0, the unit is not
        # marked failed). Ctrl-C keeps the shell's convention.
        return 0 if stop.signum == signal.SIGTERM else 130
    logging.getLogger("aeroweaver").info(
        "%s: %d rounds, %d holds, %d messages sent",
        cfg.uav,
        stats.rounds,
        stats.holds,
        stats.messages_sent,
    )
    return 0


def cmd_mission(args: argparse.Namespace) -> int:
    from aeroweaver_edge.mesh import build_zenoh_config
    from aeroweaver_edge.orchestration.mission import MissionStartOptions, start_mission
    from aeroweaver_edge.orchestration.view import LiveView, print_mission

    world_mesh = None
    if args.keys:
        mesh, world_mesh = _secured_mission_meshes(args)
    else:
        mesh = parse_config(
            {"listen": args.listen or ["tcp/127.0.0.1:0"], "connect": args.connect or [],
             "namespace": args.namespace},
            MeshConfig,
            "mesh flags",
        )  # fmt: skip
    build_zenoh_config(mesh)  # a bad endpoint, namespace or key file is an error now
    if args.json:
        check_output_file(Path(args.json), "--json")
    llm = None if args.no_llm else _llm_from_args(args)
    opts = MissionStartOptions(
        text=args.text, swarm=args.swarm, mesh=mesh, llm=llm, roster_wait_s=args.roster_wait,
        top_k=args.top_k,
        sim_world=args.sim_world, seed=args.seed, episodes=args.episodes,
        max_rounds=args.rounds, world_mesh=world_mesh if args.sim_world else None,
    )  # fmt: skip

    async def go() -> dict[str, Any]:
        if llm is not None and llm.base_url is None:
            from aeroweaver_edge.llm.embedded import EmbeddedServer

            async with EmbeddedServer() as server:
                local = llm.model_copy(update={"base_url": server.base_url, "model": server.model})
                return await start_mission(replace(opts, llm=local), LiveView().on_round)
        return await start_mission(opts, LiveView().on_round)

    try:
        out = _run(go())
    except Stopped:
        print("aeroweaver: stopped by the operator", file=sys.stderr)
        return 130
    from rich.console import Console

    from aeroweaver_edge.json_out import write_json_file

    print_mission(out["mission"], Console())
    print(f"mission ended: {out['ended']}; wall {out['wall_s']:.1f} s")
    if args.json:
        write_json_file(Path(args.json), out)
        print(f"mission record written to {args.json}")
    return 0


def _secured_mission_meshes(args: argparse.Namespace) -> tuple[MeshConfig, MeshConfig | None]:
    """``mission start --keys DIR``: the Commander's (and the world's) secured ``[mesh]``
    from a swarm directory made by ``aeroweaver keys init``."""
    from aeroweaver_edge.config import ConfigError
    from aeroweaver_edge.security import render
    from aeroweaver_edge.security.identity import COMMANDER, WORLD, SwarmPki
    from aeroweaver_edge.security.pki import PkiError

    try:
        pki = SwarmPki.load(Path(args.keys))
    except (PkiError, OSError) as exc:
        raise ConfigError(f"--keys {args.keys}: {exc}") from None
    if pki.swarm != args.swarm:
        raise ConfigError(
            f"--keys {args.keys} is for swarm {pki.swarm!r}, not {args.swarm!r}",
            f"pass --swarm {pki.swarm}",
        )
    out: list[MeshConfig | None] = []
    for name in (COMMANDER, WORLD):
        if name not in pki.identities.members:
            out.append(None)
            continue
        try:
            cfg = render.mesh_config(
                pki, name, listen=args.listen or ["tls/127.0.0.1:0"], connect=args.connect or [],
                namespace=args.namespace,
            )  # fmt: skip
        except (PkiError, ValueError) as exc:
            raise ConfigError(f"--keys {args.keys}: {exc}") from None
        out.append(cfg)
    cmdr, world = out
    if cmdr is None:
        raise ConfigError(f"--keys {args.keys}: no {COMMANDER!r} identity in that swarm")
    if args.sim_world and world is None:
        raise ConfigError(f"--keys {args.keys}: --sim-world needs the {WORLD!r} identity")
    return cmdr, world


def cmd_probe(args: argparse.Namespace) -> int:
    """Exit status follows the verdict (``llm.probe.EXIT_STATUS``)."""
    from aeroweaver_edge.llm.probe import ProbeResult
    from aeroweaver_edge.orchestration.llm import probe, shared_llm

    llm_cfg = _llm_from_args(args)

    async def go() -> ProbeResult:
        async with shared_llm(llm_cfg, needed=True) as (llm, _source):
            return await probe(llm)

    try:
        result = _run(go())
    except Stopped:
        return 130
    print(result.line())
    return result.exit_status


def cmd_memory(args: argparse.Namespace) -> int:
    """``memory stats|export|check DIR``: read-only views of experience-memory files."""
    from aeroweaver_edge.agent import memory_tools as tools

    files = tools.memory_files(Path(args.dir))
    if args.memory_command == "stats":
        data = tools.stats(files)
        if args.json:
            from aeroweaver_edge.json_out import dumps

            print(dumps(data))
            return 0
        print(
            f"{data['records']} records ({data['shared_records']} shared by peers), "
            f"{data['rewards']} rewards, {data['runs']} runs in {len(files)} file(s)"
        )
        for task, roles in data["by_task"].items():
            print(f"  {task}: " + ", ".join(f"{role} {n}" for role, n in roles.items()))
        return 0
    if args.memory_command == "export":
        if args.output:
            out = Path(args.output)
            check_output_file(out, "--output")
            out.parent.mkdir(parents=True, exist_ok=True)
            with out.open("w", encoding="utf-8") as f:
                n = tools.export_jsonl(files, f)
            print(f"{n} records written to {args.output}", file=sys.stderr)
        else:
            tools.export_jsonl(files, sys.stdout)
        return 0
    problems = tools.check(files)
    bad = 0
    for path, found in problems.items():
        print(f"{path}: {'ok' if not found else f'{len(found)} problem(s)'}")
        for problem in found[:20]:
            print(f"  {problem}")
        bad += bool(found)
    return 1 if bad else 0


def cmd_bench(args: argparse.Namespace) -> int:
    if args.what == "memory":
        from aeroweaver_edge.bench import memory

        return memory.main(["--records", str(args.records)])
    if args.what == "memory-kill":
        from aeroweaver_edge.bench import memory_kill

        return memory_kill.main(["--kills", str(args.kills)])
    if args.what == "kill-restart":
        from aeroweaver_edge.bench import kill_restart

        return kill_restart.main(["--cycles", str(args.kills)])
    if args.what == "reference":
        from aeroweaver_edge.bench import reference

        argv = ["--seeds", *map(str, args.seeds)]
        if args.tasks:
            argv += ["--tasks", *args.tasks]
        return reference.main(argv)
    if args.what == "scale":
        from aeroweaver_edge.bench import scale

        argv = ["--sizes", *map(str, args.sizes or [3, 10, 25, 50]), "--rounds", str(args.rounds)]
        argv += ["--seed", str(args.seed), "--task", args.task]
        if args.in_process:
            argv.append("--in-process")
        return scale.main(argv)
    if args.what == "mavlink":  # flight link: setpoint rate and command round trip
        from aeroweaver_edge.bench import mavlink

        return mavlink.main(["--seconds", str(args.seconds)])
    if args.what == "security":  # TLS / ACL / signature overhead, per message and per round
        from aeroweaver_edge.bench import security

        argv = ["--runs", *map(str, args.sizes or [3, 10]), "--rounds", str(args.rounds)]
        return security.main([*argv, "--seed", str(args.seed), "--task", args.task])
    if args.what == "fuzz":  # hostile payloads over every key
        from aeroweaver_edge.bench import fuzz_wire

        argv = ["--cases", str(args.cases), "--seed", str(args.seed)]
        return fuzz_wire.main([*argv, *(["--insecure"] if args.insecure else [])])
    if args.what == "llm_latency":
        from aeroweaver_edge.bench import llm_latency

        return llm_latency.main(["--uavs", str(args.uavs), "--rounds", str(args.rounds)])
    if args.what == "weights":  # the embedded model's weight formats: prompt tokens/s
        from aeroweaver_edge.bench import weights

        return weights.main([])
    raise AssertionError(f"unknown benchmark {args.what!r}")  # argparse choices


def cmd_signing_key(args: argparse.Namespace) -> int:
    """flight: provision a MAVLink 2 signing key file (0600) for one vehicle."""
    from aeroweaver_edge.vehicle.mavlink.signing import write_key

    path = Path(args.path)
    if path.exists() and not args.force:
        print(f"aeroweaver: {path} exists; use --force to replace it", file=sys.stderr)
        return 2
    write_key(path)
    print(f"wrote a 32-byte signing key to {path} (mode 0600); install the same key on the "
          "autopilot over a wired link, never over radio")  # fmt: skip
    return 0


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
    p.add_argument("--llm-deadline", type=finite(), help="seconds per LLM decision (default 20)")


PROBE_EPILOG = (
    "exit status: 0 ok; 3 usable without correction (logprobs rejected, degenerate or low "
    "label mass); 4 auth refused (401/403); 5 not found (404: URL or model); 6 unreachable "
    "(refused, DNS); 7 timeout; 8 other endpoint failure (bad request, 5xx, not a chat API); "
    "2 usage error"
)


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="aeroweaver", description=__doc__.split("\n")[0])
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("sim", help="fly a simulated swarm mission (world + daemons + Commander)")
    s.add_argument(
        "task",
        nargs="?",
        type=canonical_task,
        choices=TASK_NAMES,
        default=None,
        help="benchmark task (default: coverage, or the mission's)",
    )
    s.add_argument("--mission", help='natural-language mission, e.g. "Cover the three landmarks"')
    s.add_argument(
        "--uavs",
        type=int_in(1, MAX_UAVS),
        default=None,
        help=f"UAVs we fly, 1..{MAX_UAVS} (default: the task's team, or the mission's)",
    )
    s.add_argument("--seed", type=int, default=1)
    s.add_argument("--episodes", type=int_in(1), default=1)
    s.add_argument(
        "--rounds", type=int_in(1), default=defaults.MAX_ROUNDS, help="horizon in rounds"
    )
    s.add_argument("--processes", action="store_true", help="one OS process per daemon")
    s.add_argument("--selector", choices=["llm", "scripted"], default="llm")
    s.add_argument(
        "--beta",
        type=finite(strict=False),
        default=defaults.BETA,
        help="experience correction weight, >= 0 (0: plain)",
    )
    s.add_argument(
        "--top-k", type=int_in(1), default=defaults.TOP_K, help="task skills activated per UAV"
    )
    s.add_argument(
        "--history", type=_history_rounds, default=defaults.HISTORY_ROUNDS, metavar="ROUNDS",
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
    s.add_argument(
        "--deadline",
        type=finite(),
        default=defaults.DEADLINE_S,
        help="seconds a round may take (> 0)",
    )
    s.add_argument("--json", metavar="PATH", help="write the run summary as JSON")
    s.add_argument(
        "--trace", metavar="PATH", help="write the per-round trace as JSON Lines (docs/traces.md)"
    )
    s.add_argument("--quiet", action="store_true", help="no per-round view")
    s.add_argument(
        "--link", choices=["sim", "mavlink", "mavsdk"], default="sim",
        help="vehicle link: in-process (sim) or real MAVLink bytes to emulated autopilots",
    )  # fmt: skip
    s.add_argument("--personality", choices=["px4", "ardupilot"], default="px4",
                   help="emulated autopilot type (with --link mavlink)")  # fmt: skip
    s.add_argument(
        "--insecure", action="store_true",
        help="plain loopback TCP: no TLS, ACL or signatures (default: a throw-away PKI per run, "
        "every session mutually authenticated, ACL-checked and signed)",
    )  # fmt: skip
    s.add_argument(
        "--console",
        action="store_true",
        help="serve the live web console next to the run (prints its URL)",
    )
    s.add_argument(
        "--console-port",
        type=int_in(0, 65535),
        default=8765,
        metavar="PORT",
        help="console HTTP port (default 8765; 0: any free port)",
    )
    s.add_argument("--console-host", default="127.0.0.1", help="console HTTP address")
    s.add_argument(
        "--pace",
        type=finite(strict=False),
        default=None,
        metavar="SECONDS",
        help="wall-clock floor per round (default 0, or 0.5 with --console)",
    )
    s.add_argument(
        "--approval",
        choices=["normal", "strict"],
        default="normal",
        help="operator approval level of the daemons (strict: take-off waits)",
    )
    _add_llm_flags(s)
    s.set_defaults(func=cmd_sim)

    d = sub.add_parser(
        "daemon",
        help="run one UAV daemon",
        description="Run one UAV daemon. Under systemd (Type=notify) it sends READY=1 once "
        "its mesh is open and its vehicle link started, WATCHDOG=1 while its event loop "
        "keeps up, STOPPING=1 on SIGTERM, and exits 0. Skills come from "
        "$AEROWEAVER_SKILLS_DIR if set.",
    )
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
    ms.add_argument(
        "--keys", metavar="DIR",
        help="secured swarm: the directory from `aeroweaver keys init` (runs as cmdr; the "
        "sim world as world); endpoints are then tls/",
    )  # fmt: skip
    ms.add_argument("--roster-wait", type=finite(), default=3.0, help="seconds to discover daemons")
    ms.add_argument("--sim-world", action="store_true", help="also run the kinematic world")
    ms.add_argument("--seed", type=int, default=1)
    ms.add_argument("--episodes", type=int_in(1), default=1)
    ms.add_argument("--rounds", type=int_in(1), default=defaults.MAX_ROUNDS)
    ms.add_argument("--no-llm", action="store_true", help="rule-based parsing and roles only")
    ms.add_argument(
        "--top-k", type=int_in(1), default=defaults.TOP_K, help="task skills activated per UAV"
    )
    ms.add_argument("--json", metavar="PATH", help="write task record, assignments, outcome")
    _add_llm_flags(ms)
    ms.set_defaults(func=cmd_mission)

    pr = sub.add_parser("probe", help="classify an endpoint's logprob support", epilog=PROBE_EPILOG)
    _add_llm_flags(pr)
    pr.set_defaults(func=cmd_probe)

    mem = sub.add_parser("memory", help="inspect experience-memory files (read-only)")
    memsub = mem.add_subparsers(dest="memory_command", required=True)
    mst = memsub.add_parser("stats", help="record counts by task and role")
    mst.add_argument("dir", help="a --memory-dir (or one memory file)")
    mst.add_argument("--json", action="store_true", help="print the counts as JSON")
    mex = memsub.add_parser("export", help="every record as JSON lines")
    mex.add_argument("dir", help="a --memory-dir (or one memory file)")
    mex.add_argument("-o", "--output", metavar="PATH", help="write here instead of stdout")
    mck = memsub.add_parser(
        "check", help="integrity and consistency; exit 1 when a file has problems"
    )
    mck.add_argument("dir", help="a --memory-dir (or one memory file)")
    mem.set_defaults(func=cmd_memory)

    from aeroweaver_edge.security.cli import add_parsers as add_security_parsers

    add_security_parsers(sub)  # keys init|rotate|show, router
    from aeroweaver_edge.cli_operator import add_parsers as add_operator_parsers

    add_operator_parsers(sub)  # console, approve, mcp

    from aeroweaver_edge.baselines.cli import add_parser as add_central

    add_central(sub)  # a baseline's central node as its own process

    b = sub.add_parser("bench", help="benchmarks that print figures")
    b.add_argument(
        "what",
        choices=BENCH_WHATS,
        help="run: the benchmark (tasks x conditions x seeds; 'aeroweaver bench run --help'); "
        "with no name and any runner flags, 'aeroweaver bench [--quick] ...' is 'bench run'",
    )
    b.add_argument("--records", type=int_in(1), default=10_000, help="memory: records per role")
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
    b.add_argument("--uavs", type=int, default=3, help="llm_latency: UAVs sharing the server")
    b.add_argument("--cases", type=int_in(1), default=100_000, help="fuzz: payloads")
    b.add_argument("--insecure", action="store_true", help="fuzz: no signature layer")
    b.set_defaults(func=cmd_bench)

    # flight: emulated autopilots and signing keys (docs/flight.md)
    from aeroweaver_edge.sim.emulator.cli import add_parser as add_emulator

    add_emulator(sub)
    k = sub.add_parser("signing-key", help="create a MAVLink 2 signing key file (0600)")
    k.add_argument("path")
    k.add_argument("--force", action="store_true", help="replace an existing key file")
    k.set_defaults(func=cmd_signing_key)
    return p


BENCH_WHATS = [
    "run",
    "memory",
    "memory-kill",
    "kill-restart",
    "scale",
    "reference",
    "mavlink",
    "llm_latency",
    "weights",
    "security",
    "fuzz",
]


def _bench_run_args(argv: Sequence[str]) -> tuple[bool, list[str]] | None:
    """``[-v] bench run ...``, or ``bench`` naming no other benchmark (``bench --quick``,
    ``bench --tasks coverage``): (verbose, the runner's own arguments), else None. The
    benchmark runner has its own parser (its --seeds, --tasks, --rounds mean other things)."""
    args = list(argv)
    verbose = False
    while args and args[0] in ("-v", "--verbose"):
        verbose, args = True, args[1:]
    if args[:2] == ["bench", "run"]:
        return verbose, args[2:]
    rest = args[1:]
    help_only = bool(rest) and all(a in ("-h", "--help") for a in rest)
    if args[:1] == ["bench"] and not help_only and not set(rest) & set(BENCH_WHATS):
        return verbose, rest
    return None


def main(argv: Sequence[str] | None = None) -> int:
    bench_run = _bench_run_args(sys.argv[1:] if argv is None else argv)
    if bench_run is not None:
        from aeroweaver_edge.bench import runner

        verbose, rest = bench_run
        logging.basicConfig(
            level=logging.DEBUG if verbose else logging.WARNING,
            format="%(asctime)s %(levelname)s %(name)s: %(message)s",
            stream=sys.stderr,
        )
        try:
            return runner.main(rest)
        except (KeyboardInterrupt, asyncio.CancelledError):
            print("aeroweaver: bench stopped; rerun the same command to resume", file=sys.stderr)
            return 130
        except Exception as exc:
            return report(exc, verbose=verbose)
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.WARNING,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        return int(args.func(args))
    except KeyboardInterrupt:
        return 130
    except (Stopped, asyncio.CancelledError):
        return 130
    except Exception as exc:
        return report(exc, verbose=args.verbose)


if __name__ == "__main__":
    sys.exit(main())
