"""The Commander's and the simulated world's mesh sessions for ``aeroweaver mcp --keys DIR``.

On a secured swarm only the ``cmdr`` identity may publish a mission and only ``world`` may
publish under ``sim/``: ``start_mission`` opens a session as each, from the same swarm
directory and with the operator session's endpoints, as ``mission start --keys`` does.
"""

from __future__ import annotations

from pathlib import Path

from aeroweaver_edge.config import ConfigError, MeshConfig, parse_config
from aeroweaver_edge.mesh.session import build_zenoh_config


def spare_listen(base: MeshConfig) -> list[str]:
    """Listen endpoints for one more session beside ``base``: its ephemeral ones (port 0),
    never a fixed port the operator session already holds."""
    kept = [ep for ep in base.listen if ep.rsplit(":", 1)[-1] == "0"]
    if kept or base.connect:
        return kept
    return ["tls/127.0.0.1:0"]


def secured_sessions(
    keys: Path, swarm: str, base: MeshConfig, *, sim_world: bool
) -> tuple[MeshConfig | None, MeshConfig | None]:
    """(cmdr, world) ``[mesh]`` settings from a ``keys init`` directory; None for an identity
    the directory does not have. ``--sim-world`` without a world identity is a ConfigError
    now, not a refusal after the operator asked to start."""
    from aeroweaver_edge.security.identity import COMMANDER, WORLD, SwarmPki
    from aeroweaver_edge.security.key_files import PkiError

    try:
        pki = SwarmPki.load(keys)
    except (PkiError, OSError) as exc:
        raise ConfigError(f"--keys {keys}: {exc}") from None
    if pki.swarm != swarm:
        raise ConfigError(f"--keys {keys} is for swarm {pki.swarm!r}, not {swarm!r}",
                          f"pass --swarm {pki.swarm}")  # fmt: skip
    out: list[MeshConfig | None] = []
    for name in (COMMANDER, WORLD):
        if name not in pki.identities.members:
            out.append(None)
            continue
        try:
            sec = pki.security_for(name)
        except PkiError as exc:
            raise ConfigError(f"--keys {keys}: {exc}") from None
        data = {**base.model_dump(), "listen": spare_listen(base), "security": sec.model_dump()}
        cfg = parse_config(data, MeshConfig, f"--keys {keys} ({name})")
        build_zenoh_config(cfg)  # a missing key file: an error now, not at start_mission
        out.append(cfg)
    cmdr, world = out
    if sim_world and world is None:
        raise ConfigError(
            f"--keys {keys}: --sim-world needs the {WORLD!r} identity",
            "provision it with aeroweaver keys init, or drop --sim-world",
        )
    return cmdr, world


__all__ = ["secured_sessions", "spare_listen"]
