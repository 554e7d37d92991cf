"""``--keys DIR`` alone tells ``mission start``, ``console``, ``approve`` and ``mcp`` the swarm
and the router; flags still override the endpoints; a mismatched ``--swarm`` is refused."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest

from aeroweaver_edge.cli.main import main
from aeroweaver_edge.cli.operator import mesh_from_args
from aeroweaver_edge.config import ConfigError
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.orchestration import mission
from aeroweaver_edge.provision.keys_dir import SWARM_FILE, SwarmDir, resolve_swarm

ROUTER = "tls/127.0.0.1:17447"


@pytest.fixture(scope="module")
def keys(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("keys") / "D"
    assert main(["keys", "init", "--swarm", "s", "--uavs", "2", "--out", str(out),
                 "--loopback", "--port", "17447"]) == 0  # fmt: skip
    return out


def operator_args(keys: Path | None, **flags: Any) -> argparse.Namespace:
    base = {"keys": str(keys) if keys else None, "swarm": None, "connect": None, "listen": None,
            "namespace": None, "identity": "operator", "mesh_config": None}  # fmt: skip
    return argparse.Namespace(**{**base, **flags})


def test_console_and_mcp_find_swarm_and_router_in_the_directory(keys: Path) -> None:
    args = operator_args(keys)
    cfg = mesh_from_args(args)
    assert args.swarm == "s"
    assert cfg.connect == [ROUTER]
    assert cfg.listen == ["tls/127.0.0.1:0"]
    assert cfg.security is not None
    assert cfg.security.identity == "operator"


def test_flags_override_the_directory(keys: Path) -> None:
    args = operator_args(keys, swarm="s", connect=["tls/127.0.0.1:17999"],
                         listen=["tls/127.0.0.1:17998"], identity="observer")  # fmt: skip
    cfg = mesh_from_args(args)
    assert cfg.connect == ["tls/127.0.0.1:17999"]
    assert cfg.listen == ["tls/127.0.0.1:17998"]
    assert cfg.security is not None
    assert cfg.security.identity == "observer"


def test_a_different_swarm_is_refused(keys: Path) -> None:
    with pytest.raises(ConfigError, match="is for swarm 's', not 'other'"):
        mesh_from_args(operator_args(keys, swarm="other"))
    assert resolve_swarm(None, None) == "default"
    assert resolve_swarm("x", None) == "x"


def test_mission_start_needs_only_keys(
    keys: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    seen: list[mission.MissionStartOptions] = []

    async def fake(opts: mission.MissionStartOptions, *_: Any, **__: Any) -> dict[str, Any]:
        seen.append(opts)
        raise UserError("stopped by the test")

    monkeypatch.setattr(mission, "start_mission", fake)
    argv = ["mission", "start", "Cover the landmarks", "--keys", str(keys), "--no-llm"]
    assert main([*argv, "--sim-world"]) == 2
    assert "stopped by the test" in capsys.readouterr().err
    [opts] = seen
    assert opts.swarm == "s"
    assert opts.mesh.connect == [ROUTER]
    assert opts.mesh.security is not None
    assert opts.mesh.security.identity == "cmdr"
    assert opts.world_mesh is not None
    assert opts.world_mesh.security is not None
    assert opts.world_mesh.security.identity == "world"
    assert opts.world_mesh.connect == [ROUTER]
    assert main([*argv, "--connect", "tls/127.0.0.1:17999"]) == 2
    assert seen[-1].mesh.connect == ["tls/127.0.0.1:17999"]
    assert seen[-1].world_mesh is None


def test_a_directory_without_swarm_toml_still_names_its_swarm(keys: Path, tmp_path: Path) -> None:
    import shutil

    old = tmp_path / "old"
    shutil.copytree(keys, old)
    (old / SWARM_FILE).unlink()
    sd = SwarmDir.open(old)
    assert (sd.swarm, sd.connect) == ("s", ())
    assert sd.mesh("cmdr", connect=[ROUTER]).connect == [ROUTER]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('swarm = "t"\nconnect = []\n', "does not match the signed identity list"),
        ('swarm = "s"\nconnect = ["tls/127.0.0.1:99999"]\n', "port 99999 is outside"),
        ('swarm = "s"\nconnect = "tls/127.0.0.1:7447"\n', "a list of endpoints"),
        ("swarm = \n", "not valid TOML"),
    ],
)
def test_a_damaged_swarm_toml_is_one_line_and_exit_2(
    keys: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, message: str
) -> None:
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(keys, bad)
    (bad / SWARM_FILE).write_text(text)
    rc = main(["mission", "start", "Cover the landmarks", "--keys", str(bad), "--no-llm"])
    err = capsys.readouterr().err
    assert rc == 2
    assert message in err
    assert err.count("\n") == 1


def test_mcp_needs_only_keys_and_starts_missions_as_cmdr(
    keys: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("mcp")
    from aeroweaver_edge.mcp_server import server

    seen: list[server.McpOptions] = []

    async def fake(opts: server.McpOptions, *_: Any, **__: Any) -> None:
        seen.append(opts)
        raise UserError("stopped by the test")

    monkeypatch.setattr(server, "serve", fake)
    assert main(["mcp", "--keys", str(keys)]) == 2
    assert "stopped by the test" in capsys.readouterr().err
    [opts] = seen
    assert opts.swarm == "s"
    assert opts.mesh.connect == [ROUTER]
    assert opts.mesh.security is not None
    assert opts.mesh.security.identity == "operator"
    assert opts.commander_mesh is not None
    assert opts.commander_mesh.connect == [ROUTER]
    assert opts.commander_mesh.security is not None
    assert opts.commander_mesh.security.identity == "cmdr"


def test_a_written_mesh_toml_works_as_mesh_config(keys: Path) -> None:
    args = operator_args(None, mesh_config=str(keys / "operator" / "mesh.toml"))
    cfg = mesh_from_args(args)
    assert args.swarm == "s"  # the file names its swarm
    assert cfg.connect == [ROUTER]
    assert cfg.security is not None
    assert cfg.security.identity == "operator"
    assert cfg == SwarmDir.open(keys).mesh("operator")  # the same as --keys DIR builds
