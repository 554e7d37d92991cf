"""``aeroweaver``: run a daemon, a simulated swarm, a probe or a benchmark.

Every user error is one line on stderr naming the cause and the fix, exit status 2
(``cli.errors``); tracebacks only with ``-v``. Outputs, memory directories, the API-key
variable, the task and the skill tree are checked before any work starts (``cli.checks``).
"""

from __future__ import annotations

import argparse
import asyncio
import importlib.util
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aeroweaver_edge.cli import early as cli_early  # cli_early first: SIGTERM
from aeroweaver_edge.cli.checks import (
    check_api_key_env,
    check_llm_url,
    check_memory_dir,
    check_memory_path,
    check_output_file,
    check_skills,
    check_task,
    config_value,
    finite,
    int_in,
    mission_text,
)
from aeroweaver_edge.cli.errors import ArgumentParser, report
from aeroweaver_edge.config import (
    MAX_UAVS,
    AgentConfig,
    LLMConfig,
    MeshConfig,
    SimConfig,
    UavConfig,
    load_config,
    parse_config,
)
from aeroweaver_edge.contracts import defaults
from aeroweaver_edge.contracts.endpoints import endpoint_arg
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.runtime import log_setup, plugins
from aeroweaver_edge.runtime.signals import Stopped, forget_early_stops, stop_before_loop
from aeroweaver_edge.runtime.signals import run_until_signal as _run
from aeroweaver_edge.tasks import TASK_NAMES, canonical_task

if TYPE_CHECKING:
    from aeroweaver_edge.daemon.uav_daemon import UavDaemon
    from aeroweaver_edge.provision.keys_dir import SwarmDir


def _estimator(text: str) -> str:
    """``--estimator``: the canonical name, or one line naming the problem (exit 2)."""
    from aeroweaver_edge.agent.estimators import Estimator

    try:
        return Estimator.parse(text).name
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _scripted_base(text: str) -> str:
    """``--base``: the canonical name, or one line naming the problem (exit 2)."""
    from aeroweaver_edge.agent.scripted import Base

    try:
        return Base.parse(text).name
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


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
    from aeroweaver_edge.orchestration.view import LiveView, print_mission, print_summary
    from commander.plan import MissionPlan

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
    # flag > environment > default; a bad variable is one line, before any start
    from aeroweaver_edge.agent import choices

    if args.base is not None and args.selector != "scripted":
        raise UserError(
            f"--base {args.base}: a scripted base needs --selector scripted",
            "add --selector scripted, or drop --base",
        )
    estimator = choices.resolve("estimator", args.estimator)
    scripted_base = choices.resolve("scripted_base", args.base)
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
        share_every=args.share_experience,
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
        estimator=estimator,
        scripted_base=scripted_base,
    )
    view = None if args.quiet else LiveView()
    if args.console:
        from aeroweaver_edge.cli.operator import require_extra

        require_extra("console")
        from aeroweaver_edge.console.server import with_console

        run = with_console(opts, args.console_host, args.console_port, view)
    else:

        def planned(plan: MissionPlan) -> None:
            if view is not None:  # the mission table before the rounds, not after them
                print_mission(plan.as_dict(), view.console)

        run = run_swarm(opts, on_round=view.on_round if view else None, on_plan=planned)
    try:
        summary = _run(run)
    except (KeyboardInterrupt, Stopped):
        print("aeroweaver: stopped by the operator; every UAV was told to hold", file=sys.stderr)
        return 130
    data = summary.as_dict()
    shown = view is not None and not args.console
    print_summary({**data, "mission": None} if shown else data)
    if args.json:
        write_json(summary, Path(args.json))
        print(f"summary written to {args.json}")
    return 0


def cmd_daemon(args: argparse.Namespace) -> int:
    from aeroweaver_edge.runtime.run_dir import attach_to_run

    # A SIGTERM (the parent-death signal, systemctl stop) before the event loop handles
    # signals -- imports, config, sessions opening -- must still run the ``finally`` below,
    # or a run whose daemons were all still starting leaves its directory behind.
    previous = signal.signal(signal.SIGTERM, stop_before_loop)
    member = None
    try:
        # Started by a simulated run: die with it, and the last one out removes its
        # directory. Inside the ``try``: an orphan signals itself here.
        member = attach_to_run(os.environ)
        return _daemon(args)
    except Stopped as stop:  # stopped before the loop ran
        return 0 if stop.signum == signal.SIGTERM else 130
    finally:
        # The loop puts SIGTERM back to its default when it closes: ignore it while leaving.
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        forget_early_stops()
        if member is not None:
            member.leave()
        # The CLI process keeps ignoring SIGTERM to its very end (interpreter shutdown puts
        # any Python handler back to the default action, which a late signal would die of);
        # a program that called us in-process gets its own handler back.
        if previous is not cli_early.exit_early:
            signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)


STOP_BOUND_S = 2.0


class StopBound:
    """A stop by signal ends the process at most ``bound_s`` after the daemon's own flight
    clean-up (hold or land, report, close the link): what may still be running then -- a model
    loading in a thread that cannot be cancelled, an LLM server finishing a request --
    holds nothing that matters, and systemd (or the operator) should not wait for it.
    The flight clean-up itself (``UavDaemon.running``) is never cut short."""

    def __init__(self, bound_s: float) -> None:
        self.bound_s = bound_s
        self.daemon: UavDaemon | None = None
        self._armed = False

    def arm(self, status: int) -> None:
        """Start the bound; a repeated stop (another SIGTERM) does not restart it."""
        if self._armed:
            return
        self._armed = True
        threading.Thread(target=self._watch, args=(status,), name="stop-bound", daemon=True).start()

    def _watch(self, status: int) -> None:
        while self.daemon is not None and self.daemon.running:  # holding, landing, reporting
            time.sleep(0.05)
        time.sleep(self.bound_s)  # then the rest of the clean-up (closing the session) gets this
        logging.getLogger("aeroweaver").info(
            "stopping: clean-up still running %.0f s after the stop; exiting now", self.bound_s
        )
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)


def _daemon(args: argparse.Namespace) -> int:
    from aeroweaver_edge.agent.choices import with_env_overrides
    from aeroweaver_edge.daemon.app import run_daemon
    from aeroweaver_edge.mesh.session import build_zenoh_config
    from aeroweaver_edge.runtime.run_dir import ENV_PARENT
    from aeroweaver_edge.runtime.systemd_notify import Supervision

    cfg = load_config(args.config, UavConfig)
    # AEROWEAVER_ESTIMATOR / AEROWEAVER_SCRIPTED_BASE override the file (agent.choices)
    cfg = cfg.model_copy(update={"agent": with_env_overrides(cfg.agent)})
    build_zenoh_config(cfg.mesh)  # a bad endpoint or namespace: a config error, now
    if cfg.agent.memory_required:
        check_memory_path(cfg.agent.memory_path)
    if cfg.agent.selector in ("llm", "hmas2"):
        check_api_key_env(cfg.llm.api_key_env)
        check_llm_url(cfg.llm.base_url, "llm.base_url")
    check_skills()
    supervision = Supervision.from_env()
    bound = StopBound(STOP_BOUND_S)

    async def supervised() -> Any:
        def ready(daemon: UavDaemon) -> None:
            bound.daemon = daemon
            supervision.ready(f"{cfg.uav} up: mesh open, vehicle link started")

        try:
            # A daemon a simulated run started ends with that run's world; any other is a
            # service: missions come and go, and only a signal stops it.
            return await run_daemon(cfg, on_ready=ready, service=ENV_PARENT not in os.environ)
        finally:
            await supervision.aclose()

    def stopping(signum: int) -> None:
        line = f"{cfg.uav} stopping on {signal.Signals(signum).name}: holding"
        logging.getLogger("aeroweaver").info("%s", line)
        supervision.stopping(line)
        bound.arm(0 if signum == signal.SIGTERM else 130)

    def late_sigterm(signum: int, _frame: object) -> None:
        bound.arm(0)  # the flight is done; what is left of the teardown gets the bound

    try:
        stats = _run(supervised(), on_signal=stopping, sigterm_after=late_sigterm)
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
    from rich.console import Console

    from aeroweaver_edge.mesh.session import build_zenoh_config
    from aeroweaver_edge.orchestration.mission import (
        MissionHooks,
        MissionStartOptions,
        start_mission,
    )
    from aeroweaver_edge.orchestration.view import FieldView, LiveView, print_mission
    from aeroweaver_edge.provision.keys_dir import SwarmDir, resolve_swarm

    world_mesh = None
    keys = SwarmDir.open(args.keys) if args.keys else None
    swarm = resolve_swarm(args.swarm, keys)
    if keys is not None:
        mesh, world_mesh = _secured_mission_meshes(args, keys)
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
        text=args.text, swarm=swarm, mesh=mesh, llm=llm, roster_wait_s=args.roster_wait,
        top_k=args.top_k,
        sim_world=args.sim_world, seed=args.seed, episodes=args.episodes,
        max_rounds=args.rounds, world_mesh=world_mesh if args.sim_world else None,
        lost_grace_s=args.lost_grace, pace_s=args.pace,
    )  # fmt: skip
    console = Console(highlight=False)
    field: list[FieldView] = []

    def planned(mission: dict[str, Any]) -> None:
        # The plan first, then the run: the operator sees who flies what before it flies.
        print_mission(mission, console)
        if not args.sim_world:
            field.append(FieldView(sorted(mission["assignments"]), console))
        console.print(f"mission {mission['mission_id']} published; flying", markup=False)

    def heard(rep: Any) -> None:
        if field:
            field[0].on_report(rep)

    live = LiveView(console)
    hooks = MissionHooks(on_plan=planned, on_report=heard, on_round=live.on_round)

    async def go() -> dict[str, Any]:
        if llm is not None and llm.base_url is None:
            from aeroweaver_edge.llm.embedded import EmbeddedServer

            async with EmbeddedServer() as server:
                local = llm.model_copy(update={"base_url": server.base_url, "model": server.model})
                return await start_mission(replace(opts, llm=local), hooks=hooks)
        return await start_mission(opts, hooks=hooks)

    try:
        out = _run(go())
    except Stopped:
        print("aeroweaver: stopped by the operator", file=sys.stderr)
        return 130
    from aeroweaver_edge.runtime.json_out import write_json_file

    print(f"mission {out['mission']['mission_id']} ended: {out['ended']}; "
          f"wall {out['wall_s']:.1f} s; episodes {len(out['episodes'])}")  # fmt: skip
    _print_contact(out)
    if args.json:
        write_json_file(Path(args.json), out)
        print(f"mission record written to {args.json}")
    if out["out_of_contact"]:
        print(
            f"aeroweaver: mission ended without contact to {', '.join(out['out_of_contact'])} "
            "(they hold by themselves, then land or return: [vehicle] on_link_loss); check the "
            "router and their links",
            file=sys.stderr,
        )
        return 1
    return 0


def _print_contact(out: dict[str, Any]) -> None:
    """Lost and rejoined UAVs, and what protected the mission (as ``sim`` prints them)."""
    lost = out.get("lost_uavs") or {}
    if lost:
        where = ", ".join(f"{u} (episode {w[0]}, round {w[1] + 1})" for u, w in lost.items())
        print(f"lost contact: {where}")
    if out.get("rejoined_uavs"):
        print("rejoined: " + ", ".join(f"{u} x{n}" for u, n in out["rejoined_uavs"].items()))
    sec = out.get("security") or {}
    on = [k for k in ("tls", "acl", "signed") if sec.get(k)]
    what = "secured: " + ", ".join(on) if on else "INSECURE (no TLS, ACL or signatures)"
    print(f"{what}; refused {sec.get('rejected_total', 0)}")


def _secured_mission_meshes(
    args: argparse.Namespace, keys: SwarmDir
) -> tuple[MeshConfig, MeshConfig | None]:
    """``mission start --keys DIR``: the Commander's (and the world's) secured ``[mesh]``
    from a swarm directory made by ``aeroweaver keys init`` (flags override its endpoints)."""
    from aeroweaver_edge.config import ConfigError
    from aeroweaver_edge.security.identity import COMMANDER, WORLD

    flags = {"listen": args.listen, "connect": args.connect, "namespace": args.namespace}
    cmdr = keys.mesh(COMMANDER, **flags)
    if args.sim_world and not keys.has(WORLD):
        raise ConfigError(f"--keys {args.keys}: --sim-world needs the {WORLD!r} identity")
    world = keys.mesh(WORLD, **flags) if keys.has(WORLD) else None
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
    from aeroweaver_edge.agent.memory import tools

    files = tools.memory_files(Path(args.dir))
    if args.memory_command == "stats":
        data = tools.stats(files)
        if args.json:
            from aeroweaver_edge.runtime.json_out import dumps

            print(dumps(data))
            return 0
        print(
            f"{data['records']} records ({data['shared_records']} shared by peers), "
            f"{data['rewards']} rewards, {data['runs']} runs in {len(files)} file(s)"
        )
        for task, roles in data["by_task"].items():
            print(f"  {task}: " + ", ".join(f"{role} {n}" for role, n in roles.items()))
        for f in data["files"]:  # per daemon: whose records it holds (peers' are capped)
            print(f"  {Path(f['path']).name}: " + ", ".join(
                f"{who} {c['records']} ({c['bytes']} B{', shared' if c['shared'] else ''})"
                for who, c in f["by_sender"].items()))  # fmt: skip
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
    p.add_argument(
        "--llm-deadline", type=config_value(LLMConfig, "deadline_s"),
        help="seconds per LLM decision (default 20)",
    )  # fmt: skip


PROBE_EPILOG = (
    "exit status: 0 ok; 3 usable without correction (logprobs rejected, degenerate or low "
    "label mass); 4 auth refused (401/403); 5 not found (404: URL or model); 6 unreachable "
    "(refused, DNS); 7 timeout; 8 other endpoint failure (bad request, 5xx, not a chat API); "
    "2 usage error"
)


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="aeroweaver", description=__doc__.split("\n")[0])
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
    s.add_argument(
        "--mission", type=mission_text,
        help='natural-language mission (UTF-8, at most 8 KiB), e.g. "Cover the three landmarks"',
    )  # fmt: skip
    s.add_argument(
        "--uavs",
        type=int_in(1, MAX_UAVS),
        default=None,
        help=f"UAVs we fly, 1..{MAX_UAVS} (default: the task's team, or the mission's)",
    )
    s.add_argument("--seed", type=config_value(SimConfig, "seed"), default=1)
    s.add_argument("--episodes", type=int_in(1), default=1)
    s.add_argument(
        "--rounds",
        type=config_value(SimConfig, "max_rounds"),
        default=defaults.MAX_ROUNDS,
        help="horizon in rounds",
    )
    s.add_argument("--processes", action="store_true", help="one OS process per daemon")
    s.add_argument("--selector", choices=["llm", "scripted"], default="llm")
    s.add_argument(
        "--beta",
        type=config_value(AgentConfig, "beta"),
        default=defaults.BETA,
        help="experience correction weight, >= 0 (0: plain)",
    )
    s.add_argument(
        "--estimator", type=_estimator, default=None,
        help="advantage estimator: paper (default), horizon:H, centre, support:M, shrink:K, "
        "scale or tscore, comma-joined (horizon:3,centre); overrides AEROWEAVER_ESTIMATOR; "
        "docs/adaptation.md",
    )  # fmt: skip
    s.add_argument(
        "--base", type=_scripted_base, default=None,
        help="scripted selector's base: reference (default), hold-biased, position-biased, "
        "noisy[:SD], optionally @T; overrides AEROWEAVER_SCRIPTED_BASE",
    )  # fmt: skip
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
        "--share-experience", choices=["episode", "round"], default="episode",
        help="peers' experience arrives as each episode ends (episode) or from the next "
        "round on ([agent] share_every; docs/adaptation.md)",
    )  # fmt: skip
    s.add_argument(
        "--deadline",
        type=config_value(SimConfig, "deadline_s"),
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
        type=config_value(SimConfig, "pace_s"),
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
    ms.add_argument(
        "text", type=mission_text, help="the mission in natural language (UTF-8, at most 8 KiB)"
    )
    ms.add_argument("--swarm", help="swarm id (default: the --keys directory's, else 'default')")
    ms.add_argument(
        "--connect", action="append", type=endpoint_arg("connect"),
        help="zenoh endpoint of a daemon or router (default: the --keys directory's)",
    )  # fmt: skip
    ms.add_argument(
        "--listen", action="append", type=endpoint_arg("listen"),
        help="zenoh endpoint to listen on",
    )  # fmt: skip
    ms.add_argument("--namespace", help="zenoh namespace of the swarm")
    ms.add_argument(
        "--keys", metavar="DIR",
        help="secured swarm: the directory from `aeroweaver keys init` (runs as cmdr; the "
        "sim world as world); it names the swarm and the router, so --swarm and --connect "
        "are not needed; endpoints are then tls/",
    )  # fmt: skip
    ms.add_argument("--roster-wait", type=finite(), default=3.0, help="seconds to discover daemons")
    ms.add_argument("--sim-world", action="store_true", help="also run the kinematic world")
    ms.add_argument("--seed", type=config_value(SimConfig, "seed"), default=1)
    ms.add_argument("--episodes", type=int_in(1), default=1)
    ms.add_argument(
        "--rounds", type=config_value(SimConfig, "max_rounds"), default=defaults.MAX_ROUNDS
    )
    ms.add_argument("--no-llm", action="store_true", help="rule-based parsing and roles only")
    ms.add_argument(
        "--top-k", type=int_in(1), default=defaults.TOP_K, help="task skills activated per UAV"
    )
    ms.add_argument(
        "--pace", type=finite(strict=False), default=0.0, metavar="SECONDS",
        help="with --sim-world: wall-clock floor per round (default 0)",
    )  # fmt: skip
    ms.add_argument(
        "--lost-grace", type=finite(), default=10.0, metavar="SECONDS",
        help="stop the mission once every UAV has been out of contact this long (default 10)",
    )  # fmt: skip
    ms.add_argument(
        "--json", metavar="PATH",
        help="write task record, assignments, outcome, lost_uavs, rejoined_uavs, security",
    )  # fmt: skip
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

    from aeroweaver_edge.cli.keys import add_parsers as add_security_parsers

    add_security_parsers(sub)  # keys init|rotate|show, router
    from aeroweaver_edge.cli.operator import add_parsers as add_operator_parsers

    add_operator_parsers(sub)  # console, approve, mcp

    _add_extension_parsers(sub)  # bench, central: another distribution's (the lab)

    # flight: emulated autopilots and signing keys (docs/flight.md)
    from aeroweaver_edge.sim.emulator.cli import add_parser as add_emulator

    add_emulator(sub)
    k = sub.add_parser("signing-key", help="create a MAVLink 2 signing key file (0600)")
    k.add_argument("path")
    k.add_argument("--force", action="store_true", help="replace an existing key file")
    k.set_defaults(func=cmd_signing_key)
    _add_log_flags(p)
    return p


BUILTIN = frozenset({
    "sim", "daemon", "mission", "probe", "memory", "keys", "router", "console", "approve",
    "mcp", "emulator", "signing-key",
})  # fmt: skip


def _extension_call(given: Sequence[str]) -> tuple[str, list[str], bool] | None:
    """``[-v] NAME ...`` where NAME is another distribution's command (installed or known):
    (NAME, its arguments, verbose); else None (a built-in command, or no command)."""
    verbose = bool(given) and given[0] in ("-v", "--verbose")
    rest = list(given[verbose:])
    if not rest or rest[0] in BUILTIN or rest[0].startswith("-"):
        return None
    known = set(plugins.names(plugins.COMMANDS)) | {"bench", "central"}
    return (rest[0], rest[1:], verbose) if rest[0] in known else None


def _add_extension_parsers(sub: Any) -> None:
    """``aeroweaver --help`` lists the installed extensions' commands; ``main`` hands them
    their arguments before this parser runs."""
    for name in plugins.names(plugins.COMMANDS):
        if name not in BUILTIN:
            command = plugins.command(name)
            sub.add_parser(name, help=command.help if command else "", add_help=False)


def _add_log_flags(top: argparse.ArgumentParser) -> None:
    """``-v`` and ``--log-level`` on the program and on every (sub)command, so they work
    before or after it (``aeroweaver daemon --config uav.toml -v``). A subcommand's copy
    sets the value only when given (``SUPPRESS``), never resetting the program's."""
    parsers = [top]
    while parsers:
        parser = parsers.pop()
        outer = parser is top
        parser.add_argument(
            "-v", "--verbose", action="store_true",
            default=False if outer else argparse.SUPPRESS,
            help="debug logging (tracebacks on errors)",
        )  # fmt: skip
        parser.add_argument(
            "--log-level", type=str.upper, choices=log_setup.LEVELS, metavar="LEVEL",
            default=None if outer else argparse.SUPPRESS,
            help="DEBUG, INFO, WARNING, ERROR or CRITICAL (default: INFO for daemon and "
            "router, WARNING otherwise; -v is DEBUG)",
        )  # fmt: skip
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                parsers.extend(dict.fromkeys(action.choices.values()))


def main(argv: Sequence[str] | None = None) -> int:
    given = list(sys.argv[1:] if argv is None else argv)
    extension = _extension_call(given)
    if extension is not None:  # ``aeroweaver bench ...``: the command parses its own flags
        name, rest, verbose = extension
        try:
            command = plugins.load(plugins.COMMANDS, name)
        except UserError as exc:
            return report(exc, verbose=verbose)
        return int(command.main(rest, verbose))
    args = build_parser().parse_args(argv)
    if args.func is not cmd_daemon and signal.getsignal(signal.SIGTERM) is cli_early.exit_early:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)  # the command's own runner handles it
    log_setup.setup(args.command, verbose=args.verbose, log_level=args.log_level)
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
