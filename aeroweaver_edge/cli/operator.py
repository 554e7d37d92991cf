"""``aeroweaver console``, ``aeroweaver approve`` and ``aeroweaver mcp``: watching and operating
a swarm from the ground (a web page, one command, an agent client).

Kept out of ``cli.py`` (it gains one line); the web and MCP libraries are optional extras,
imported when a command runs. Every command joins the mesh with the settings given here:
plain loopback endpoints, or a secured identity (``--keys DIR --identity NAME`` from
``aeroweaver keys init``, or ``--mesh-config FILE`` with a ``[mesh]`` table).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import tomllib
from pathlib import Path
from typing import Any

from aeroweaver_edge.contracts.endpoints import endpoint_arg
from aeroweaver_edge.contracts.errors import UserError

CONSOLE_PORT = 8765  # console.server.DEFAULT_PORT (not imported: the web extra is optional)
EXTRA_HINT = {
    "console": ("starlette", "uvicorn"),
    "mcp": ("mcp",),
}


def require_extra(extra: str) -> None:
    missing = [m for m in EXTRA_HINT[extra] if importlib.util.find_spec(m) is None]
    if missing:
        raise UserError(
            f"this command needs the optional {extra!r} extra ({', '.join(missing)} missing)",
            f"pip install 'aeroweaver-edge[{extra}]'",
        )


def add_mesh_flags(p: argparse.ArgumentParser, identity: str) -> None:
    p.add_argument(
        "--swarm", help="swarm id, the aw/<swarm>/ key prefix (default: the --keys "
        "directory's, else 'default')",
    )  # fmt: skip
    p.add_argument(
        "--connect", action="append", type=endpoint_arg("connect"),
        help="zenoh endpoint of a router or a daemon (default: the --keys directory's)",
    )  # fmt: skip
    p.add_argument(
        "--listen", action="append", type=endpoint_arg("listen"),
        help="zenoh endpoint to listen on",
    )  # fmt: skip
    p.add_argument("--namespace", help="zenoh namespace of the swarm")
    p.add_argument(
        "--keys", metavar="DIR",
        help="a swarm directory from `aeroweaver keys init`: it names the swarm and the "
        "router, so --swarm and --connect are not needed",
    )  # fmt: skip
    p.add_argument(
        "--identity", default=identity, help=f"identity in --keys to join as (default {identity})"
    )
    p.add_argument(
        "--mesh-config", metavar="FILE", help="TOML/JSON with a [mesh] table (instead of flags)"
    )


def mesh_from_args(args: argparse.Namespace) -> Any:
    """The MeshConfig the flags describe; any problem is one ConfigError/UserError. With
    ``--keys DIR`` the directory supplies the swarm (``args.swarm`` is filled in here when
    not given) and the endpoints to dial (``security.keys_dir``); a ``--mesh-config`` file
    with a top-level ``swarm`` (``keys init``'s ``mesh.toml``) supplies the swarm too."""
    from aeroweaver_edge.config import ConfigError, MeshConfig, parse_config
    from aeroweaver_edge.mesh.session import build_zenoh_config
    from aeroweaver_edge.provision.keys_dir import SwarmDir, resolve_swarm

    keys = SwarmDir.open(args.keys) if args.keys else None
    flag_swarm = args.swarm
    args.swarm = resolve_swarm(args.swarm, keys)
    if args.mesh_config:
        path = Path(args.mesh_config)
        try:
            raw = path.read_bytes()
            data = json.loads(raw) if path.suffix == ".json" else tomllib.loads(raw.decode())
        except (OSError, ValueError) as exc:
            raise ConfigError(f"{path}: cannot read a config: {exc}") from None
        if not isinstance(data, dict) or not isinstance(data.get("mesh"), dict):
            raise ConfigError(f"{path}: no [mesh] table")
        cfg = parse_config(data["mesh"], MeshConfig, f"{path} [mesh]")
        if flag_swarm is None and keys is None and isinstance(data.get("swarm"), str):
            args.swarm = data["swarm"]  # a mesh.toml from keys init names its swarm
    elif keys is not None:
        cfg = keys.mesh(
            args.identity, listen=args.listen, connect=args.connect, namespace=args.namespace
        )
    else:
        fields: dict[str, Any] = {
            "listen": args.listen or ["tcp/127.0.0.1:0"],
            "connect": args.connect or [],
            "namespace": args.namespace,
        }
        cfg = parse_config(fields, MeshConfig, "mesh flags")
    build_zenoh_config(cfg)  # a bad endpoint or missing key file: an error now, not mid-run
    return cfg


def add_parsers(sub: Any) -> None:
    """Register ``console``, ``approve`` and ``mcp`` on the main parser's subparsers."""
    c = sub.add_parser(
        "console",
        help="web console: a live map of a swarm, or a replay of a trace",
        description="Serve the console page (http://HOST:PORT/). Live: join the swarm's mesh "
        "as an observer (with the operator identity, the page may also stop the mission and "
        "approve vehicle actions, each behind a typed confirmation). --replay: play a "
        "finished run from its trace (aeroweaver sim --trace).",
    )
    add_mesh_flags(c, "operator")
    c.add_argument("--replay", metavar="TRACE", help="replay this trace (JSON Lines) instead")
    c.add_argument("--host", default="127.0.0.1", help="HTTP address (default 127.0.0.1)")
    c.add_argument("--port", type=int, default=CONSOLE_PORT, help=f"HTTP port ({CONSOLE_PORT})")
    c.add_argument("--read-only", action="store_true", help="never act, even as the operator")
    c.set_defaults(func=cmd_console)

    a = sub.add_parser(
        "approve",
        help="approve a vehicle action (take off, land, return home) for one UAV",
        description="Send an operator approval to one UAV and wait for its acknowledgement. "
        "The UAV checks the sender (an approver identity, signed when secured), records it "
        "and uses it once (strict) or for its mission's take-off (normal); it expires.",
    )
    add_mesh_flags(a, "operator")
    a.add_argument("--uav", required=True, help="the UAV, e.g. uav0")
    a.add_argument(
        "--action", required=True, help="takeoff, land or return_home (take_off: takeoff)"
    )
    a.add_argument("--ttl", type=float, default=300.0, help="seconds it stays valid (default 300)")
    a.add_argument("--mission", default="", help="only for this mission id (default: any)")
    a.add_argument("--by", help="the person approving, for the record (default: login name)")
    a.add_argument("--wait", type=float, default=5.0, help="seconds to wait for the UAV")
    a.set_defaults(func=cmd_approve)

    m = sub.add_parser(
        "mcp",
        help="Model Context Protocol server: the swarm for agent clients (stdio or HTTP)",
        description="Expose the swarm to MCP clients: resources (roster, UAV state, mission, "
        "last decisions, approvals) and tools (plan, start, stop, approve, trace). Acting "
        "tools say what they will do first and need confirm plus the operator token "
        "($AEROWEAVER_OPERATOR_TOKEN, or --operator-token-env).",
    )
    add_mesh_flags(m, "operator")
    m.add_argument("--transport", choices=["stdio", "http"], default="stdio")
    m.add_argument("--host", default="127.0.0.1", help="http: address (default 127.0.0.1)")
    m.add_argument("--port", type=int, default=8766, help="http: port (default 8766)")
    m.add_argument(
        "--operator-token-env", default="AEROWEAVER_OPERATOR_TOKEN",
        help="environment variable holding the operator token (unset: read-only server)",
    )  # fmt: skip
    m.add_argument(
        "--commander-config", metavar="FILE",
        help="[mesh] for the Commander session start_mission opens; default: the cmdr "
        "identity of --keys DIR (and world for --sim-world), else the same mesh settings",
    )  # fmt: skip
    m.add_argument("--sim-world", action="store_true", help="start_mission also runs the world")
    m.add_argument("--pace", type=float, default=0.0, help="sim world: seconds per round floor")
    m.set_defaults(func=cmd_mcp)


# -- commands ---------------------------------------------------------------------------


def cmd_console(args: argparse.Namespace) -> int:
    require_extra("console")
    from aeroweaver_edge.console.frames import TraceError
    from aeroweaver_edge.console.server import Console
    from aeroweaver_edge.runtime.signals import Stopped
    from aeroweaver_edge.runtime.signals import run_until_signal as _run

    if args.replay and (args.connect or args.keys or args.mesh_config):
        raise UserError("--replay plays a file: it takes no mesh flags")
    mesh = None if args.replay else mesh_from_args(args)

    async def go() -> None:
        console = Console(args.host, args.port)
        if args.replay:
            try:
                console.replay(Path(args.replay))
            except TraceError as exc:
                raise UserError(str(exc), "pass a trace from aeroweaver sim --trace") from None
        async with console:
            if mesh is not None:
                await console.connect(mesh, args.swarm, act=not args.read_only)
            what = f"replay of {args.replay}" if args.replay else f"swarm {args.swarm!r}"
            print(f"console: {console.url} ({what}); Ctrl-C to stop", flush=True)
            await console.serve_forever()

    try:
        _run(go())
    except Stopped:
        return 0
    return 0


def cmd_approve(args: argparse.Namespace) -> int:
    from aeroweaver_edge.contracts.wire import ApprovalRecord
    from aeroweaver_edge.mesh.session import Mesh
    from aeroweaver_edge.runtime.signals import Stopped
    from aeroweaver_edge.runtime.signals import run_until_signal as _run
    from aeroweaver_edge.safety.approval import parse_action
    from aeroweaver_edge.safety.operator import OperatorLink

    try:
        action = parse_action(args.action)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if not 0 < args.ttl <= 86_400:
        raise UserError(f"--ttl {args.ttl:g}: must be within (0, 86400] seconds")
    mesh_cfg = mesh_from_args(args)

    async def go() -> ApprovalRecord:
        name = mesh_cfg.security.identity if mesh_cfg.security is not None else "operator"
        async with await Mesh.open(mesh_cfg, node_id=name) as mesh:
            link = OperatorLink(mesh, args.swarm, person=args.by)
            return await link.approve(args.uav, action, args.ttl, mission_id=args.mission,
                                      timeout_s=args.wait)  # fmt: skip

    try:
        rec = _run(go())
    except Stopped:
        return 130
    print(
        f"{args.uav}: {rec.action} approved by {rec.by or rec.sender} (id {rec.id}), "
        f"valid for {rec.expires - rec.received:.0f} s, recorded by the UAV"
    )
    return 0


def cmd_mcp(args: argparse.Namespace) -> int:
    require_extra("mcp")
    from aeroweaver_edge.mcp_server.server import McpOptions, serve
    from aeroweaver_edge.runtime.signals import Stopped
    from aeroweaver_edge.runtime.signals import run_until_signal as _run

    mesh_cfg = mesh_from_args(args)
    commander_cfg, world_cfg = mesh_cfg, None
    if args.keys and not args.mesh_config:  # the cmdr and world identities of the same swarm
        from aeroweaver_edge.mcp_server.sessions import secured_sessions

        cmdr, world_cfg = secured_sessions(
            Path(args.keys), args.swarm, mesh_cfg, sim_world=args.sim_world
        )
        commander_cfg = cmdr or mesh_cfg  # none: start_mission says which identity it needs
    if args.commander_config:
        commander_cfg = mesh_from_args(
            argparse.Namespace(**{**vars(args), "mesh_config": args.commander_config})
        )
    token = os.environ.get(args.operator_token_env) or None
    opts = McpOptions(
        swarm=args.swarm, mesh=mesh_cfg, commander_mesh=commander_cfg, operator_token=token,
        sim_world=args.sim_world, pace_s=args.pace, world_mesh=world_cfg,
    )  # fmt: skip
    if args.transport == "http":
        print(f"aeroweaver mcp: http://{args.host}:{args.port}/mcp", file=sys.stderr, flush=True)
    try:
        _run(serve(opts, args.transport, args.host, args.port))
    except Stopped:
        return 0
    return 0


__all__ = ["add_parsers", "mesh_from_args", "require_extra"]
