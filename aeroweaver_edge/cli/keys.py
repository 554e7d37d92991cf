"""``aeroweaver keys init|rotate|show`` and ``aeroweaver router``.

Kept out of ``cli.py`` so the main parser only gains one line; heavy imports (cryptography,
zenoh) happen when a command runs.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aeroweaver_edge.cli.checks import int_in
from aeroweaver_edge.config import MAX_UAVS
from aeroweaver_edge.contracts.endpoints import endpoint_arg, is_host
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.provision import sitl
from aeroweaver_edge.provision.daemon_toml import VEHICLE_PORT, VEHICLES

MAX_DAYS = 3650  # ten years: longer is a typo (and keys should be rotated long before)
DEFAULT_PORT = 7447  # Zenoh's own default port
FIELD_LISTEN = f"tls/0.0.0.0:{DEFAULT_PORT}"


def add_parsers(sub: Any) -> None:
    """Register the ``keys`` and ``router`` commands on the main parser's subparsers."""
    k = sub.add_parser("keys", help="provision and manage a swarm's identities (X.509 + Ed25519)")
    ksub = k.add_subparsers(dest="keys_command", required=True)

    ki = ksub.add_parser(
        "init",
        help="make a CA, every identity's keys and per-process configs",
        description="Make a swarm directory: a CA, every identity's keys, a complete "
        "commented uav.toml per UAV, a zenoh.json5 per process, the ground tools' mesh.toml "
        "and swarm.toml (so `--keys DIR` is all mission start, console, approve and mcp "
        "need). Built in a temporary sibling directory and renamed at the end: a refusal or "
        "failure leaves nothing. --loopback: the whole swarm on this machine (a rehearsal).",
    )
    ki.add_argument("--swarm", required=True, help="swarm id (the aw/<swarm>/ key prefix)")
    ki.add_argument(
        "--uavs", type=int_in(1, MAX_UAVS), required=True,
        help=f"number of UAVs: uav0..uavN-1 (1..{MAX_UAVS})",
    )  # fmt: skip
    ki.add_argument("--out", required=True, help="new (or empty) directory for the swarm")
    ki.add_argument(
        "--host",
        action="append",
        default=[],
        metavar="[NAME=]ADDR",
        help="extra certificate SAN (IP or DNS name): for every identity, or NAME=ADDR for one",
    )
    ki.add_argument(
        "--days", type=int_in(1, MAX_DAYS), default=30, help="certificate lifetime (default 30)"
    )
    ki.add_argument(
        "--ca-days", type=int_in(1, MAX_DAYS), default=365, help="CA lifetime (default 365)"
    )
    ki.add_argument(
        "--loopback", action="store_true",
        help="every process on this machine: the router on tls/127.0.0.1:PORT, uavN on "
        "PORT+1+N, ground tools on a port of their own; everything dials the router",
    )  # fmt: skip
    ki.add_argument(
        "--port", type=int_in(1, 65535), default=DEFAULT_PORT,
        help=f"--loopback: the router's port (default {DEFAULT_PORT})",
    )  # fmt: skip
    ki.add_argument(
        "--listen", type=endpoint_arg("listen"),
        help=f"where the router and each UAV listen, one per machine (default {FIELD_LISTEN}); "
        "ground tools listen on tls/127.0.0.1:0",
    )  # fmt: skip
    ki.add_argument(
        "--connect", action="append", default=[], type=endpoint_arg("connect"),
        help="endpoint(s) to dial: the router or a seed (also written to swarm.toml)",
    )  # fmt: skip
    ki.add_argument(
        "--vehicle", choices=VEHICLES, default="sim",
        help="the daemons' vehicle link: sim (wait for a simulated world, mission start "
        "--sim-world), emulator (`aeroweaver emulator --uavs N` on this machine; needs "
        "--loopback), sitl (your own ArduCopter SITL build, one instance per UAV on this "
        "machine; needs --loopback), mavlink or mavsdk (a real autopilot sending to udpin://0.0.0.0:"
        "VEHICLE_PORT, or VEHICLE_PORT+N with --loopback)",
    )  # fmt: skip
    ki.add_argument(
        "--selector", choices=["llm", "scripted"], default=None,
        help="the daemons' [agent] selector: llm (the embedded SmolLM2 until [llm] names an "
        "endpoint) or scripted (the task's reference policy, not an LLM); default: scripted "
        "with --vehicle emulator (a rehearsal that needs no model), else llm",
    )  # fmt: skip
    ki.add_argument(
        "--vehicle-port", type=int_in(1, 65535), default=VEHICLE_PORT,
        help=f"UDP port vehicle 0 sends MAVLink to (default {VEHICLE_PORT}; "
        "the emulator's --port-base)",
    )  # fmt: skip
    ki.add_argument("--mode", choices=["peer", "client"], default="peer", help="UAV session mode")
    ki.add_argument("--namespace", help="zenoh namespace of the swarm (isolation, not security)")
    ki.add_argument(
        "--install-dir", help="where this directory will live on the vehicles (paths in configs)"
    )
    ki.add_argument(
        "--state-dir",
        help="boot counters on the vehicles (default <install-dir>/state; /var/lib/aeroweaver)",
    )
    ki.add_argument(
        "--key-dir",
        help="where each UAV daemon reads its private keys ({name} = identity), e.g. "
        "/run/credentials/aeroweaver-daemon@{name}.service (systemd LoadCredential=)",
    )
    ki.add_argument(
        "--router-key-dir",
        help="where the router reads its private key "
        "(e.g. /run/credentials/aeroweaver-router.service)",
    )
    ki.add_argument(
        "--no-verify-name",
        action="store_true",
        help="do not require the dialled address in the peer's certificate (dynamic addresses)",
    )
    for role in ("central", "observer", "router"):
        ki.add_argument(f"--no-{role}", action="store_true", help=f"no {role} identity")
    ki.set_defaults(func=cmd_keys_init)

    kr = ksub.add_parser("rotate", help="re-issue one identity's keys and re-sign the list")
    kr.add_argument("--dir", required=True, help="the swarm directory from `keys init`")
    kr.add_argument("--identity", required=True, help="e.g. uav3, cmdr, world")
    kr.set_defaults(func=cmd_keys_rotate)

    ks = ksub.add_parser("show", help="list identities, roles, fingerprints and expiry")
    ks.add_argument("--dir", required=True, help="the swarm directory from `keys init`")
    ks.add_argument("--json", action="store_true", help="machine-readable output")
    ks.set_defaults(func=cmd_keys_show)

    r = sub.add_parser("router", help="run a Zenoh router (LAN) from a zenoh config file")
    r.add_argument("--config", required=True, help="router zenoh.json5 (from `keys init`)")
    r.add_argument(
        "--insecure", action="store_true", help="allow plain links or no ACL (never in the field)"
    )
    r.set_defaults(func=cmd_router)


def _fail(msg: str) -> int:
    print(f"aeroweaver: {msg}", file=sys.stderr)
    return 2


def _hosts(items: list[str], members: dict[str, Any]) -> tuple[list[str], dict[str, list[str]]]:
    """``--host`` values: ADDR for every certificate, NAME=ADDR for one identity's."""
    common: list[str] = []
    per: dict[str, list[str]] = {}
    for item in items:
        name, sep, addr = item.rpartition("=") if "=" in item else ("", "", item)
        if sep and name not in members:
            known = ", ".join(sorted(members))
            raise UserError(f"--host {item!r}: no identity {name!r} in this swarm (known: {known})")
        if not is_host(addr):
            raise UserError(f"--host {item!r}: {addr!r} is not an IP address or a DNS name")
        (per.setdefault(name, []) if sep else common).append(addr)
    return common, per


def cmd_keys_init(args: argparse.Namespace) -> int:
    from aeroweaver_edge.config import check_id
    from aeroweaver_edge.security.identity import default_members

    try:
        check_id(args.swarm, "swarm id")
        members = default_members(
            args.uavs,
            central=not args.no_central,
            observer=not args.no_observer,
            router=not args.no_router,
        )
        plan = _plan(args, members)
        out = _check_out(Path(args.out))
    except (UserError, ValueError) as exc:
        return _fail(f"keys init: {exc}")
    try:
        _build_atomically(out, lambda tmp: _write_swarm(tmp, out, args, members, plan))
    except OSError as exc:
        name = str(exc.filename or "")
        where = out if not name or f"/.{out.name}." in name else name  # not the temp name
        return _fail(f"keys init: cannot write {where}: {exc.strerror or exc}")
    except (UserError, ValueError) as exc:
        return _fail(f"keys init: {exc}")
    _print_done(out, args, members, plan)
    return 0


@dataclass(frozen=True)
class _Plan:
    """Who listens where and dials what (decided before anything is written)."""

    listen: dict[str, list[str]]
    connect: dict[str, list[str]]
    ground_connect: list[str]  # what ground tools dial: swarm.toml
    hosts: tuple[list[str], dict[str, list[str]]]  # certificate SANs: all, per identity


def _plan(args: argparse.Namespace, members: dict[str, Any]) -> _Plan:
    from aeroweaver_edge.config import MeshConfig, endpoint_is_secure
    from aeroweaver_edge.mesh.session import build_zenoh_config
    from aeroweaver_edge.provision.keys_dir import GROUND_LISTEN
    from aeroweaver_edge.security.identity import ROUTER
    from aeroweaver_edge.security.policy import Role

    if args.loopback and (args.listen or args.connect):
        raise UserError(
            "--loopback sets every endpoint itself (the router on tls/127.0.0.1:PORT)",
            "drop --listen/--connect, or --port to move the router",
        )
    if args.loopback and args.no_router:
        raise UserError("--loopback rehearses the field shape with its router: drop --no-router")
    if args.vehicle in ("emulator", "sitl") and not args.loopback:
        raise UserError(
            f"--vehicle {args.vehicle}: the rehearsal runs every vehicle on this machine",
            "add --loopback (or use --vehicle mavlink for real autopilots)",
        )
    for ep in [*([args.listen] if args.listen else []), *args.connect]:
        if not endpoint_is_secure(ep):
            raise UserError(f"{ep!r}: a swarm's endpoints are tls/ (or quic/)")
    if args.namespace:
        build_zenoh_config(MeshConfig(namespace=args.namespace))  # zenoh's own check, now
    uavs = sorted((n for n, r in members.items() if r is Role.UAV), key=_uav_number)
    if args.loopback:
        if args.port + len(uavs) > 65535:
            raise UserError(f"--port {args.port}: uavN listens on PORT+1+N, past 65535")
        router = f"tls/127.0.0.1:{args.port}"
        uav_listen = {u: [f"tls/127.0.0.1:{args.port + 1 + i}"] for i, u in enumerate(uavs)}
        connect = [router]
    else:
        router = args.listen or FIELD_LISTEN
        uav_listen = {u: [router] for u in uavs}  # one UAV per machine
        connect = list(args.connect)
    if args.vehicle != "sim" and args.vehicle_port + len(uavs) - 1 > 65535:
        raise UserError(
            f"--vehicle-port {args.vehicle_port}: vehicle N sends to PORT+N, past 65535"
        )
    listen: dict[str, list[str]] = {}
    dial: dict[str, list[str]] = {}
    for name, role in members.items():
        if name == ROUTER:
            listen[name], dial[name] = [router], []
        elif role is Role.UAV:
            listen[name] = [] if args.mode == "client" else uav_listen[name]
            dial[name] = connect
        else:  # ground processes share a machine: a port of their own each, on loopback
            listen[name], dial[name] = [GROUND_LISTEN], connect
    return _Plan(listen, dial, connect, _hosts(args.host, members))


def _selector(args: argparse.Namespace) -> str:
    if args.selector is not None:
        return str(args.selector)
    return "scripted" if args.vehicle in ("emulator", "sitl") else "llm"


def _uav_number(name: str) -> int:
    digits = name[len(name.rstrip("0123456789")) :]
    return int(digits) if digits else 0


def _check_out(out: Path) -> Path:
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise UserError(f"--out {out}: exists and is not a plain directory (use a new one)")
    if out.exists() and any(out.iterdir()):
        raise UserError(f"--out {out}: is not empty (use a new directory)")
    return out


def _build_atomically(out: Path, build: Any) -> None:
    """Build in a temporary sibling and rename it onto ``out`` at the end, so a failure
    leaves neither a partial directory nor a CA key lying around."""
    missing = [p for p in [out.parent, *out.parent.parents] if not p.exists()]
    top = missing[-1] if missing else None  # the highest parent this call creates
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    try:
        build(tmp)
        os.chmod(tmp, 0o755)  # certificates are public; every private key inside is 0600
        if out.exists():
            out.rmdir()  # empty (checked): the rename takes its place
        os.rename(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        d = out.parent
        while top is not None and d != top.parent:  # directories only this call made
            try:
                d.rmdir()
            except OSError:
                break
            d = d.parent
        raise


def _write_swarm(
    tmp: Path, out: Path, args: argparse.Namespace, members: dict[str, Any], plan: _Plan
) -> None:
    from aeroweaver_edge.provision import render
    from aeroweaver_edge.provision.keys_dir import SWARM_FILE, swarm_toml
    from aeroweaver_edge.security.identity import COMMANDER, OBSERVER, OPERATOR, WORLD, SwarmPki
    from aeroweaver_edge.security.pki import write_file
    from aeroweaver_edge.security.policy import Role

    common, per = plan.hosts
    pki = SwarmPki.create(tmp, args.swarm, members, hosts=common, host_of=per,
                          days=args.days, ca_days=args.ca_days)  # fmt: skip
    final = out.resolve()
    install = Path(args.install_dir) if args.install_dir else final
    state = Path(args.state_dir) if args.state_dir else install / "state"
    uses = {
        COMMANDER: "aeroweaver mission start --keys DIR (mcp --commander-config)",
        WORLD: "aeroweaver mission start --keys DIR --sim-world",
        OPERATOR: "aeroweaver console / approve / mcp --keys DIR",
        OBSERVER: "aeroweaver console --keys DIR --identity observer --read-only",
    }
    for name, role in sorted(members.items()):
        mode: render.Mode = "router" if role is Role.ROUTER else args.mode
        if role is not Role.UAV and role is not Role.ROUTER:
            mode = "peer"
        cfg = render.mesh_config(
            pki, name, listen=plan.listen[name], connect=plan.connect[name], mode=mode,
            namespace=args.namespace, install_dir=install, state_dir=state,
            key_dir={Role.UAV: args.key_dir, Role.ROUTER: args.router_key_dir}.get(role),
            verify_name=not args.no_verify_name,
        )  # fmt: skip
        d = pki.paths(name).dir
        write_file(d / "zenoh.json5", render.zenoh_json5(pki, cfg, name).encode())
        if role is Role.UAV:
            uav = render.uav_config(
                cfg, name, args.swarm, vehicle=args.vehicle, index=_uav_number(name),
                loopback=args.loopback, vehicle_port=args.vehicle_port,
                memory_path=str(state / f"{name}.sqlite3"), selector=_selector(args),
            )  # fmt: skip
            text = render.uav_toml(uav, args.vehicle, str(args.out))
            write_file(d / "uav.toml", text.encode())
        elif role is not Role.ROUTER:
            use = uses.get(name, f"the {role.value} process")
            text = render.ground_toml(cfg, name, role, args.swarm, use)
            write_file(d / "mesh.toml", text.encode())
    text = swarm_toml(args.swarm, plan.ground_connect, args.namespace)
    write_file(tmp / SWARM_FILE, text.encode())
    if args.vehicle == "sitl":  # the SITL instances' --defaults (not a secret)
        write_file(tmp / sitl.PARAMS_FILE, sitl.params_text().encode())


def _print_done(out: Path, args: argparse.Namespace, members: dict[str, Any], plan: _Plan) -> None:
    from aeroweaver_edge.security.identity import ROUTER

    uavs = sorted((n for n in members if n.startswith("uav")), key=_uav_number)
    print(f"swarm {args.swarm!r}: {len(members)} identities in {out}")
    print(f"  CA key: {out / 'ca' / 'ca.key'} (keep it off the vehicles)")
    if ROUTER in members:
        print(f"  router: {out / ROUTER / 'zenoh.json5'} (listens on {plan.listen[ROUTER][0]})")
    link = {
        "sim": "wait for a simulated world (mission start --sim-world)",
        "emulator": f"aeroweaver emulator --uavs {len(uavs)}"
        + (f" --port-base {args.vehicle_port}" if args.vehicle_port != VEHICLE_PORT else ""),
        "sitl": f"your ArduCopter SITL build, one instance per UAV (the command is in each "
        f"uav.toml; defaults file {out / sitl.PARAMS_FILE})",
        "mavlink": "MAVLink from the autopilot",
        "mavsdk": "MAVSDK to the autopilot",
    }[args.vehicle]
    which = uavs[0] if len(uavs) == 1 else f"{uavs[0]}..{uavs[-1]}"
    print(f"  daemons: {out}/uavN/uav.toml for {which}, vehicle: {link}")
    where = ", ".join(plan.ground_connect) or "nothing yet: pass --connect"
    print(f"  ground: --keys {out} is enough for mission start, console, mcp (dial {where})")
    if not args.loopback:
        print("  install on each machine: ca.crt, identities.json and that identity's folder")


def cmd_keys_rotate(args: argparse.Namespace) -> int:
    from aeroweaver_edge.security.identity import SwarmPki
    from aeroweaver_edge.security.key_files import PkiError

    try:
        pki = SwarmPki.load(Path(args.dir))
        member = pki.rotate(args.identity)
    except (PkiError, OSError) as exc:
        return _fail(f"keys rotate: {exc}")
    print(
        f"{member.name}: new TLS certificate {member.tls_cert} and signing key; identity list "
        f"now version {pki.identities.version}"
    )
    print(f"  install {pki.paths(member.name).dir} on {member.name}, and identities.json on every")
    print("  machine; restart them (the identity list is read at start-up)")
    return 0


def cmd_keys_show(args: argparse.Namespace) -> int:
    from aeroweaver_edge.security.identity import SwarmPki
    from aeroweaver_edge.security.key_files import PkiError

    try:
        pki = SwarmPki.load(Path(args.dir))
        rows = pki.describe()
    except (PkiError, OSError) as exc:
        return _fail(f"keys show: {exc}")
    if args.json:
        doc = {"swarm": pki.swarm, "version": pki.identities.version, "identities": rows}
        print(json.dumps(doc, indent=2))
        return 0
    print(f"swarm {pki.swarm!r}, identity list version {pki.identities.version} (signature ok)")
    cols = ("name", "role", "signing_key", "tls_cert", "expires", "status")
    widths = [max(len(c), *(len(r[c]) for r in rows)) for c in cols]
    print("  ".join(c.ljust(w) for c, w in zip(cols, widths, strict=True)))
    for r in rows:
        print("  ".join(r[c].ljust(w) for c, w in zip(cols, widths, strict=True)))
    return 0


def cmd_router(args: argparse.Namespace) -> int:
    from aeroweaver_edge.runtime.signals import Stopped
    from aeroweaver_edge.runtime.signals import run_until_signal as _run
    from aeroweaver_edge.security.router import RouterError, check_router_config, run_router

    try:
        conf = check_router_config(Path(args.config), insecure=args.insecure)
    except RouterError as exc:
        return _fail(f"router: {exc}")
    try:
        _run(run_router(conf))
    except RouterError as exc:
        return _fail(f"router: {exc}")
    except (KeyboardInterrupt, asyncio.CancelledError, Stopped):
        return 0  # SIGTERM/SIGINT is how a router is stopped (systemctl stop): not a failure
    return 0
