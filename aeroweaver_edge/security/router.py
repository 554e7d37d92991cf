"""A LAN Zenoh router as a Python process (there is no ``zenohd`` on PyPI or in Debian).

A zenoh-python session opened in ``router`` mode routes pub/sub, queries and liveliness for
its clients and peers (docs/notes/zenoh.md). It runs the swarm ACL like every other node; the ACL
is per hop, so the router is where client-mode UAVs' writes are judged, and signatures are
what keep a compromised router from forging payloads.
"""

from __future__ import annotations

import asyncio
import json
import logging
import sys
from pathlib import Path

import zenoh

from aeroweaver_edge.config import endpoint_is_loopback, endpoint_is_secure

log = logging.getLogger(__name__)


class RouterError(RuntimeError):
    """The router config is unusable or unsafe; the message says why."""


def _get(conf: zenoh.Config, path: str) -> object:
    try:
        return json.loads(conf.get_json(path))
    except (zenoh.ZError, ValueError):
        return None


def check_router_config(path: Path, *, insecure: bool = False) -> zenoh.Config:
    """Load a JSON5 zenoh config and refuse one that would expose the swarm."""
    if not path.is_file():
        raise RouterError(f"{path}: no such file")
    try:
        conf = zenoh.Config.from_file(str(path))
    except (zenoh.ZError, ValueError) as exc:
        raise RouterError(
            f"{path}: not a valid zenoh config: {str(exc).split(' at /')[0]}"
        ) from None
    if _get(conf, "mode") != "router":
        raise RouterError(f"{path}: mode is {_get(conf, 'mode')!r}, expected 'router'")
    listen = _get(conf, "listen/endpoints")
    endpoints = [e for e in listen if isinstance(e, str)] if isinstance(listen, list) else []
    if not endpoints:
        raise RouterError(f"{path}: listen/endpoints is empty: a router must listen")
    if not insecure:
        for ep in endpoints:
            if not endpoint_is_secure(ep) and not endpoint_is_loopback(ep):
                raise RouterError(f"{path}: {ep!r} is a plain link off this machine (--insecure)")
        if any(endpoint_is_secure(ep) for ep in endpoints):
            if not _get(conf, "transport/link/tls/root_ca_certificate"):
                raise RouterError(f"{path}: TLS without root_ca_certificate trusts public CAs")
            if _get(conf, "transport/link/tls/enable_mtls") is not True:
                raise RouterError(f"{path}: TLS without enable_mtls lets anyone connect")
        if _get(conf, "access_control/enabled") is not True:
            raise RouterError(f"{path}: no access_control: the router would relay anything")
    return conf


async def run_router(conf: zenoh.Config) -> None:
    """Run until cancelled (SIGTERM / Ctrl-C); the session is always closed."""
    try:
        session = await asyncio.to_thread(zenoh.open, conf)
    except zenoh.ZError as exc:
        raise RouterError(f"cannot open the router session: {str(exc).split(' at /')[0]}") from None
    try:
        print(f"aeroweaver router {session.zid()} up", file=sys.stderr, flush=True)
        await asyncio.Event().wait()
    finally:
        await asyncio.to_thread(session.close)
