"""``aeroweaver keys`` and ``aeroweaver router`` as an operator uses them."""

from __future__ import annotations

import asyncio
import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

from aeroweaver_edge.cli.main import main
from aeroweaver_edge.config import UavConfig, load_config
from aeroweaver_edge.contracts.wire import HeaderFactory, InboxMessage, Keys
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.security.identity import SwarmPki
from tests.helpers.zenoh_net import free_port


def init(out: Path, *extra: str) -> int:
    return main(["keys", "init", "--swarm", "field", "--uavs", "2", "--out", str(out), *extra])


def test_keys_init_writes_a_usable_swarm(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "swarm"
    assert init(out, "--listen", "tls/127.0.0.1:0", "--host", "10.0.0.1") == 0
    assert "8 identities" in capsys.readouterr().out
    pki = SwarmPki.load(out)
    assert pki.swarm == "field"
    for name in pki.identities.members:
        conf = zenoh.Config.from_file(str(pki.paths(name).dir / "zenoh.json5"))
        assert json.loads(conf.get_json("access_control/enabled")) is True
        assert json.loads(conf.get_json("transport/link/tls/enable_mtls")) is True
        mode = json.loads(conf.get_json("mode"))
        assert mode == ("router" if name == "router" else "peer")
    cfg = load_config(out / "uav1" / "uav.toml", UavConfig)
    assert (cfg.uav, cfg.swarm) == ("uav1", "field")
    assert cfg.mesh.security is not None
    assert cfg.mesh.security.signing_key == str((out / "uav1" / "sign.key").resolve())
    assert cfg.mesh.security.state_dir == str((out / "state").resolve())
    mesh = await_open(cfg)  # the generated daemon config opens a secured session
    assert mesh.security_summary()["signed"] is True
    asyncio.run(mesh.aclose())


def await_open(cfg: UavConfig) -> Mesh:
    async def go() -> Mesh:
        return await Mesh.open(cfg.mesh, node_id=cfg.uav)

    return asyncio.run(go())


def test_keys_show_and_rotate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "swarm"
    assert init(out) == 0
    capsys.readouterr()
    assert main(["keys", "show", "--dir", str(out), "--json"]) == 0
    before = json.loads(capsys.readouterr().out)
    assert before["version"] == 1
    assert {r["status"] for r in before["identities"]} == {"ok"}
    assert main(["keys", "rotate", "--dir", str(out), "--identity", "uav0"]) == 0
    assert "version 2" in capsys.readouterr().out
    assert main(["keys", "show", "--dir", str(out), "--json"]) == 0
    after = json.loads(capsys.readouterr().out)
    changed = {
        a["name"] for a, b in zip(after["identities"], before["identities"], strict=True) if a != b
    }
    assert changed == {"uav0"}
    assert main(["keys", "show", "--dir", str(out)]) == 0
    table = capsys.readouterr().out
    assert "version 2 (signature ok)" in table
    assert "uav0" in table


def cli(argv: list[str]) -> int:
    """``main`` as the shell sees it: argparse's usage errors are exit status 2 too."""
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


INIT = ["keys", "init", "--swarm", "x", "--uavs", "1", "--out"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([*INIT[:5], "0", "--out", "{d}/a"], "0 is out of range (1..50)"),
        ([*INIT[:5], "100000", "--out", "{d}/a"], "100000 is out of range (1..50)"),
        (["keys", "init", "--swarm", "Bad!", "--uavs", "1", "--out", "{d}/b"], "swarm id"),
        ([*INIT, "{d}/full"], "is not empty"),
        ([*INIT, "{d}/file"], "exists and is not a plain directory"),
        ([*INIT, "{d}/c", "--host", "uav5=10.0.0.5"], "no identity 'uav5'"),
        ([*INIT, "{d}/c", "--host", "uav0=not an addr!"], "not an IP address or a DNS name"),
        ([*INIT, "{d}/c", "--host", "under_score.example"], "not an IP address or a DNS name"),
        ([*INIT, "{d}/c", "--days", "0"], "0 is out of range"),
        ([*INIT, "{d}/c", "--days", "-5"], "-5 is out of range"),
        ([*INIT, "{d}/c", "--ca-days", "0"], "0 is out of range"),
        ([*INIT, "{d}/e", "--listen", "tcp/0.0.0.0:1"], "endpoints are tls/"),
        ([*INIT, "{d}/e", "--connect", "tls/127.0.0.1:99999"], "port 99999 is outside 1..65535"),
        ([*INIT, "{d}/e", "--listen", "tls/127.0.0.1:70000"], "port 70000 is outside 0..65535"),
        ([*INIT, "{d}/e", "--connect", "tlz/10.0.0.1:7447"], "unknown protocol 'tlz'"),
        ([*INIT, "{d}/e", "--connect", "tls/10.0.0.1"], "expected host:port"),
        ([*INIT, "{d}/e", "--vehicle", "emulator"], "add --loopback"),
        ([*INIT, "{d}/e", "--loopback", "--connect", "tls/1.2.3.4:7447"], "--loopback sets"),
        ([*INIT, "{d}/e", "--loopback", "--no-router"], "drop --no-router"),
        ([*INIT, "{d}/e", "--loopback", "--port", "65535"], "past 65535"),
        ([*INIT, "{d}/e", "--vehicle", "mavlink", "--vehicle-port", "65535", "--uavs", "2"],
         "past 65535"),
        (["keys", "show", "--dir", "{d}/nothing"], "no identities.json"),
        (["keys", "rotate", "--dir", "{d}/nothing", "--identity", "uav0"], "no identities.json"),
        (["router", "--config", "{d}/none.json5"], "no such file"),
        (
            ["mission", "start", "Cover the landmarks", "--no-llm", "--connect",
             "tcp/10.0.0.2:7447"],
            "plain link off this machine",
        ),
        (
            ["mission", "start", "Cover the landmarks", "--no-llm", "--connect",
             "tcp/127.0.0.1:99999"],
            "port 99999 is outside 1..65535",
        ),
        (
            ["mission", "start", "Cover the landmarks", "--no-llm", "--listen",
             "tcp/127.0.0.1:x"],
            "port 'x' is not a number",
        ),
        (["console", "--connect", "tcp/127.0.0.1:0"], "port 0 is outside 1..65535"),
        (["mcp", "--connect", "udp/[::1:7447"], "IPv6"),
    ],
)  # fmt: skip
def test_operator_mistakes_are_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("keep me")
    (tmp_path / "file").write_text("a file")
    before = sorted(p.name for p in tmp_path.iterdir())
    rc = cli([a.replace("{d}", str(tmp_path)) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2
    assert message in err
    assert err.count("\n") == 1
    assert "Traceback" not in err
    assert (tmp_path / "full" / "x").read_text() == "keep me"
    assert (tmp_path / "file").read_text() == "a file"
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written, no temp dir


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ({"listen": {"endpoints": ["tcp/0.0.0.0:7447"]}}, "plain link off this machine"),
        ({"access_control": {"enabled": False}}, "no access_control"),
        ({"mode": "peer"}, "expected 'router'"),
        ({"listen": {"endpoints": []}}, "must listen"),
    ],
)
def test_router_refuses_an_unsafe_config(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], edit: dict[str, object], message: str
) -> None:
    out = tmp_path / "swarm"
    assert init(out) == 0
    base = zenoh.Config.from_file(str(out / "router" / "zenoh.json5"))
    doc = {
        k: json.loads(base.get_json(k)) for k in ("mode", "listen", "transport", "access_control")
    }
    for key, value in edit.items():
        doc[key] = {**doc[key], **value} if isinstance(value, dict) else value
    path = tmp_path / "router.json5"
    path.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["router", "--config", str(path)]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
def test_router_process_relays_for_its_clients_and_stops_on_sigterm(tmp_path: Path) -> None:
    port = free_port()
    out = tmp_path / "swarm"
    assert init(out, "--listen", f"tls/127.0.0.1:{port}", "--mode", "client",
                "--connect", f"tls/127.0.0.1:{port}") == 0  # fmt: skip
    proc = subprocess.Popen(
        [sys.executable, "-m", "aeroweaver_edge", "router", "--config",
         str(out / "router" / "zenoh.json5")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert proc.stderr is not None
        assert "aeroweaver router" in proc.stderr.readline()  # up and listening
        asyncio.run(_relay_through(out))
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 0


async def _relay_through(out: Path) -> None:
    keys = Keys("field")
    cfg0 = load_config(out / "uav0" / "uav.toml", UavConfig)
    cfg1 = load_config(out / "uav1" / "uav.toml", UavConfig)
    uav0 = await Mesh.open(cfg0.mesh, node_id="uav0")
    uav1 = await Mesh.open(cfg1.mesh, node_id="uav1")
    try:
        inbox = uav1.subscribe(keys.inbox("uav1"), InboxMessage)
        h = HeaderFactory("uav0")
        for _ in range(50):  # until the router knows uav1's subscription
            uav0.put(
                keys.inbox("uav1", "uav0"), InboxMessage(h=h.next(), to="uav1", round=0, kind="s")
            )
            try:
                _key, msg = await asyncio.wait_for(inbox.get(), 0.1)
                break
            except TimeoutError:
                continue
        else:
            raise AssertionError("nothing crossed the router")
        assert msg.h.sender == "uav0"
        assert uav1.codec.stats.total == 0
    finally:
        await asyncio.gather(uav0.aclose(), uav1.aclose())
