"""The shipped examples are what the code generates, and they are secured."""

from __future__ import annotations

from pathlib import Path

import pytest

from aeroweaver_edge.cli.main import main
from aeroweaver_edge.config import UavConfig, load_config

REPO = Path(__file__).resolve().parents[3]
CANONICAL = [
    "keys", "init", "--swarm", "field", "--uavs", "3",
    "--install-dir", "/etc/aeroweaver/keys", "--state-dir", "/var/lib/aeroweaver",
    "--key-dir", "/run/credentials/aeroweaver-daemon@{name}.service",
    "--router-key-dir", "/run/credentials/aeroweaver-router.service",
    "--connect", "tls/10.0.0.1:7447", "--host", "router=10.0.0.1",
]  # fmt: skip


@pytest.mark.parametrize("name", ["uav0", "cmdr", "router"])
def test_deploy_zenoh_templates_are_current(tmp_path: Path, name: str) -> None:
    """Regenerate with the command in deploy/README.md; the files must match exactly (the
    rendered configs hold paths and the ACL, no key material, so they are deterministic)."""
    out = tmp_path / "field"
    assert main([*CANONICAL, "--out", str(out)]) == 0
    shipped = (REPO / "deploy" / "zenoh" / f"{name}.json5").read_text()
    assert (out / name / "zenoh.json5").read_text() == shipped


def test_example_uav_config_is_secured_and_matches_keys_init(tmp_path: Path) -> None:
    cfg = load_config(REPO / "configs" / "uav.toml", UavConfig)
    assert cfg.mesh.security is not None
    assert all(ep.startswith("tls/") for ep in [*cfg.mesh.listen, *cfg.mesh.connect])
    out = tmp_path / "field"
    assert main([*CANONICAL, "--out", str(out)]) == 0
    generated = load_config(out / "uav0" / "uav.toml", UavConfig)
    assert cfg.mesh == generated.mesh.model_copy(update={"comm_radius_m": 55.0})
