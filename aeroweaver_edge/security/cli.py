"""``aeroweaver keys init|rotate|show`` and ``aeroweaver router``.

Kept out of ``cli.py`` so the main parser only gains one line; heavy imports (cryptography,
zenoh) happen when a command runs.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from pathlib import Path
from typing import Any


def add_parsers(sub: Any) -> None:
    """Register the ``keys`` and ``router`` commands on the main parser's subparsers."""
    k = sub.add_parser("keys", help="provision and manage a swarm's identities (X.509 + Ed25519)")
    ksub = k.add_subparsers(dest="keys_command", required=True)

    ki = ksub.add_parser("init", help="make a CA, every identity's keys and per-process configs")
    ki.add_argument("--swarm", required=True, help="swarm id (the aw/<swarm>/ key prefix)")
    ki.add_argument("--uavs", type=int, required=True, help="number of UAVs: uav0..uavN-1")
    ki.add_argument("--out", required=True, help="new directory for the swarm's key material")
    ki.add_argument(
        "--host",
        action="append",
        default=[],
        metavar="[NAME=]ADDR",
        help="extra certificate SAN (IP or DNS name): for every identity, or NAME=ADDR for one",
    )
    ki.add_argument("--days", type=int, default=30, help="certificate lifetime (default 30)")
    ki.add_argument("--ca-days", type=int, default=365, help="CA lifetime (default 365)")
    ki.add_argument("--listen", default="tls/0.0.0.0:7447", help="each process's listen endpoint")
    ki.add_argument(
        "--connect", action="append", default=[], help="endpoint(s) to dial: the router or a seed"
    )
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


def _hosts(items: list[str]) -> tuple[list[str], dict[str, list[str]]]:
    common: list[str] = []
    per: dict[str, list[str]] = {}
    for item in items:
        name, sep, addr = item.partition("=")
        if sep:
            per.setdefault(name, []).append(addr)
        else:
            common.append(item)
    return common, per


def cmd_keys_init(args: argparse.Namespace) -> int:
    from aeroweaver_edge.config import ConfigError, endpoint_is_secure
    from aeroweaver_edge.security import render
    from aeroweaver_edge.security.identity import ROUTER, SwarmPki, default_members
    from aeroweaver_edge.security.pki import PkiError, write_file
    from aeroweaver_edge.security.policy import Role

    out = Path(args.out)
    if args.uavs < 1:
        return _fail("keys init: --uavs must be at least 1")
    for ep in [args.listen, *args.connect]:
        if not endpoint_is_secure(ep):
            return _fail(f"keys init: {ep!r}: a swarm's endpoints are tls/ (or quic/)")
    if out.exists() and any(out.iterdir()):
        return _fail(f"keys init: {out} is not empty (use a new directory)")
    try:
        members = default_members(
            args.uavs,
            central=not args.no_central,
            observer=not args.no_observer,
            router=not args.no_router,
        )
        common, per = _hosts(args.host)
        pki = SwarmPki.create(out, args.swarm, members, hosts=common, host_of=per,
                              days=args.days, ca_days=args.ca_days)  # fmt: skip
        install = Path(args.install_dir) if args.install_dir else None
        state = Path(args.state_dir) if args.state_dir else None
        for name, role in sorted(members.items()):
            mode: render.Mode = "router" if role is Role.ROUTER else args.mode
            listen = [args.listen] if mode != "client" else []
            connect = [] if name == ROUTER else list(args.connect)
            cfg = render.mesh_config(
                pki, name, listen=listen, connect=connect, mode=mode, namespace=args.namespace,
                install_dir=install, state_dir=state,
                key_dir={Role.UAV: args.key_dir, Role.ROUTER: args.router_key_dir}.get(role),
                verify_name=not args.no_verify_name,
            )  # fmt: skip
            d = pki.paths(name).dir
            write_file(d / "zenoh.json5", render.zenoh_json5(pki, cfg, name).encode())
            if role is Role.UAV:
                write_file(d / "uav.toml", render.uav_toml(cfg, name, args.swarm).encode())
    except (PkiError, ConfigError, ValueError, OSError) as exc:
        return _fail(f"keys init: {exc}")
    print(f"swarm {args.swarm!r}: {len(members)} identities in {out}")
    print(f"  CA key: {out / 'ca' / 'ca.key'} (keep it off the vehicles)")
    print("  install on each machine: ca.crt, identities.json and that identity's folder")
    return 0


def cmd_keys_rotate(args: argparse.Namespace) -> int:
    from aeroweaver_edge.security.identity import SwarmPki
    from aeroweaver_edge.security.pki import PkiError

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
    from aeroweaver_edge.security.pki import PkiError

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
    from aeroweaver_edge.cli_runner import Stopped
    from aeroweaver_edge.cli_runner import run_until_signal as _run
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
