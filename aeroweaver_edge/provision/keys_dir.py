"""``--keys DIR`` on the ground: a swarm directory from ``aeroweaver keys init`` tells a ground
command (``mission start``, ``console``, ``approve``, ``mcp``) everything it needs to join,
so ``--swarm`` and ``--connect`` are not needed when the directory says them.

``keys init`` writes ``DIR/swarm.toml`` (the swarm id, the endpoints ground tools dial, the
namespace); this module reads it back and builds an identity's secured ``[mesh]`` from the
directory as it is on this machine. Flags still win: ``--connect``, ``--listen`` and
``--namespace`` replace what the file says; a ``--swarm`` that differs from the directory's
swarm is refused (its certificates and ACL are for that swarm only).

Ground processes listen on ``tls/127.0.0.1:0`` (a port the OS picks, on loopback only):
nobody dials them, and the console and ``mcp`` may run side by side as the same identity.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aeroweaver_edge.config import ConfigError, MeshConfig, check_id
from aeroweaver_edge.contracts.endpoints import endpoint_problem
from aeroweaver_edge.security.identity import SwarmPki
from aeroweaver_edge.security.key_files import PkiError

SWARM_FILE = "swarm.toml"
GROUND_LISTEN = "tls/127.0.0.1:0"
DEFAULT_SWARM = "default"  # the swarm of a plain (unsecured) command without --swarm


@dataclass(frozen=True)
class SwarmDir:
    """A provisioned swarm directory as a ground command uses it."""

    pki: SwarmPki
    swarm: str
    connect: tuple[str, ...] = ()
    namespace: str | None = None

    @classmethod
    def open(cls, path: str | Path) -> SwarmDir:
        """Load and check ``DIR`` (signed identity list, ``swarm.toml`` when present)."""
        root = Path(path)
        try:
            pki = SwarmPki.load(root)
        except (PkiError, OSError) as exc:
            raise ConfigError(f"--keys {path}: {exc}") from None
        desc = root / SWARM_FILE
        if not desc.exists():  # a directory from before swarm.toml: the identity list only
            return cls(pki, pki.swarm)
        data = _read(desc)
        where = f"--keys {path}: {desc.name}"
        swarm = data.get("swarm")
        if swarm != pki.swarm:
            raise ConfigError(
                f"{where}: swarm {swarm!r} does not match the signed identity list ({pki.swarm!r})",
                "regenerate the directory with aeroweaver keys init",
            )
        connect = data.get("connect", [])
        if not isinstance(connect, list) or not all(isinstance(e, str) for e in connect):
            raise ConfigError(f"{where}: connect must be a list of endpoints")
        for ep in connect:
            problem = endpoint_problem(ep, "connect")
            if problem is not None:
                raise ConfigError(f"{where}: connect {ep!r}: {problem}")
        namespace = data.get("namespace")
        if namespace is not None and not isinstance(namespace, str):
            raise ConfigError(f"{where}: namespace must be a string")
        return cls(pki, pki.swarm, tuple(connect), namespace)

    def has(self, identity: str) -> bool:
        return identity in self.pki.identities.members

    def mesh(
        self,
        identity: str,
        *,
        listen: list[str] | None = None,
        connect: list[str] | None = None,
        namespace: str | None = None,
    ) -> MeshConfig:
        """``identity``'s secured ``[mesh]``: flags when given, else this directory's."""
        if not self.has(identity):
            known = ", ".join(sorted(self.pki.identities.members))
            raise ConfigError(
                f"--keys {self.pki.root}: no {identity!r} identity in swarm {self.swarm!r}",
                f"use one of: {known}",
            )
        from aeroweaver_edge.provision import render

        try:
            return render.mesh_config(
                self.pki, identity, listen=listen or [GROUND_LISTEN],
                connect=connect or list(self.connect),
                namespace=namespace if namespace is not None else self.namespace,
            )  # fmt: skip
        except (PkiError, ValueError) as exc:
            raise ConfigError(f"--keys {self.pki.root}: {exc}") from None


def resolve_swarm(flag: str | None, keys: SwarmDir | None) -> str:
    """The swarm a command joins: ``--swarm``, else the keys directory's, else ``default``."""
    if keys is None:
        return flag if flag is not None else DEFAULT_SWARM
    if flag is not None and flag != keys.swarm:
        raise ConfigError(
            f"--keys {keys.pki.root} is for swarm {keys.swarm!r}, not {flag!r}",
            f"pass --swarm {keys.swarm} (or drop --swarm: the directory names its swarm)",
        )
    return keys.swarm


def swarm_toml(swarm: str, connect: list[str], namespace: str | None) -> str:
    """The text of ``DIR/swarm.toml`` (``keys init`` writes it, ``SwarmDir.open`` reads it)."""
    check_id(swarm, "swarm id")
    lines = [
        "# This swarm, for the ground tools, written by `aeroweaver keys init`. With --keys DIR",
        "# `mission start`, `console`, `approve` and `mcp` read the swarm id and the endpoints",
        "# to dial from here; --swarm must match, --connect / --namespace replace these.",
        f"swarm = {json.dumps(swarm)}",
        "# where ground tools dial in (the router, or a seed UAV); empty: pass --connect",
        f"connect = [{', '.join(json.dumps(e) for e in connect)}]",
    ]
    if namespace:
        lines += ["# zenoh namespace of the swarm", f"namespace = {json.dumps(namespace)}"]
    return "\n".join(lines) + "\n"


def _read(path: Path) -> dict[str, Any]:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None


__all__ = ["GROUND_LISTEN", "SWARM_FILE", "SwarmDir", "resolve_swarm", "swarm_toml"]
