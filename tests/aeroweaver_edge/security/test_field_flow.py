"""The README's field flow on loopback: provision with ``keys init``, start the router and
the daemons from the generated files (separate processes), run a mission with ``mission
start --keys`` (the Commander as ``cmdr``, the simulated world as ``world``), stop them.
"""

from __future__ import annotations

import asyncio
import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from aeroweaver_edge.cli.main import main
from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.security.identity import SwarmPki
from tests.helpers.swarm_procs import uavs_seen
from tests.helpers.zenoh_net import free_port

SWARM = "fs"
TEXT = "Send the secret symbol to the receiver with two drones; the eavesdropper must not read it."


def spawn(*args: str, log: Path) -> subprocess.Popen[bytes]:
    with log.open("wb") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "aeroweaver_edge", *args],
            stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
        )  # fmt: skip


async def wait_for_uavs(keys_dir: Path, router: str, uavs: set[str], timeout_s: float) -> bool:
    """The observer (a read-only identity) sees every UAV's token through the router."""
    pki = SwarmPki.load(keys_dir)
    cfg = MeshConfig(mode="client", listen=[], connect=[router],
                     security=pki.security_for("observer"),
                     zenoh_overrides={"connect/timeout_ms": "30000"})  # fmt: skip
    # (the router may still be starting: the open waits for it)
    return await uavs_seen(cfg, SWARM, uavs, timeout_s)


@pytest.mark.slow
def test_provision_start_and_fly_a_secured_mission(tmp_path: Path) -> None:
    keys, port = tmp_path / "keys", free_port()
    router = f"tls/127.0.0.1:{port}"
    # scripted, so no LLM is needed
    assert main(["keys", "init", "--swarm", SWARM, "--uavs", "2", "--out", str(keys),
                 "--listen", router, "--connect", router, "--mode", "client",
                 "--selector", "scripted"]) == 0  # fmt: skip
    procs = [spawn("router", "--config", str(keys / "router" / "zenoh.json5"),
                   log=tmp_path / "router.log")]  # fmt: skip
    try:
        for uav in ("uav0", "uav1"):
            procs.append(spawn("daemon", "--config", str(keys / uav / "uav.toml"),
                               log=tmp_path / f"{uav}.log"))  # fmt: skip
        up = asyncio.run(wait_for_uavs(keys, router, {"uav0", "uav1"}, 60.0))
        assert up, [(tmp_path / f).read_text()[-500:] for f in ("router.log", "uav0.log")]
        out = tmp_path / "mission.json"
        code = main(["mission", "start", TEXT, "--swarm", SWARM, "--keys", str(keys),
                     "--connect", router, "--sim-world", "--no-llm", "--roster-wait", "1.5",
                     "--json", str(out)])  # fmt: skip
        assert code == 0
        record = json.loads(out.read_text())
        assert record["roster"] == ["uav0", "uav1"]
        assert record["not_ready"] == []
        assert record["ended"] == "complete"
        [episode] = record["episodes"]
        assert episode["team_return"] == 4.0  # the receiver decoded the symbol
    finally:
        for p in procs:
            p.send_signal(signal.SIGTERM)
        codes = [p.wait(timeout=30) for p in procs]
    assert codes == [0, 0, 0]  # SIGTERM is how services stop: a clean exit
    for name in ("uav0", "uav1", "cmdr", "world"):  # every process counted its start
        assert (keys / "state" / f"{name}.boot").read_text() == "1\n"


@pytest.mark.slow
def test_loopback_sim_swarm_flies_with_keys_alone(tmp_path: Path) -> None:
    """``keys init --loopback --vehicle sim``: distinct ports on one machine, daemons that
    wait for a simulated world, and ``mission start --keys DIR --sim-world`` with no
    ``--swarm`` or ``--connect`` (the directory names both)."""
    keys, port = tmp_path / "keys", free_port()
    assert main(["keys", "init", "--swarm", SWARM, "--uavs", "2", "--out", str(keys),
                 "--loopback", "--port", str(port), "--vehicle", "sim",
                 "--selector", "scripted"]) == 0  # fmt: skip
    procs = [spawn("router", "--config", str(keys / "router" / "zenoh.json5"),
                   log=tmp_path / "router.log")]  # fmt: skip
    try:
        for uav in ("uav0", "uav1"):
            procs.append(spawn("daemon", "--config", str(keys / uav / "uav.toml"),
                               log=tmp_path / f"{uav}.log"))  # fmt: skip
        router = f"tls/127.0.0.1:{port}"
        up = asyncio.run(wait_for_uavs(keys, router, {"uav0", "uav1"}, 60.0))
        assert up, [(tmp_path / f).read_text()[-500:] for f in ("router.log", "uav0.log")]
        out = tmp_path / "mission.json"
        code = main(["mission", "start", TEXT, "--keys", str(keys), "--sim-world", "--no-llm",
                     "--json", str(out)])  # fmt: skip
        assert code == 0
        record = json.loads(out.read_text())
        assert record["roster"] == ["uav0", "uav1"]
        [episode] = record["episodes"]
        assert episode["team_return"] == 4.0
    finally:
        for p in procs:
            p.send_signal(signal.SIGTERM)
        codes = [p.wait(timeout=30) for p in procs]
    assert codes == [0, 0, 0]
