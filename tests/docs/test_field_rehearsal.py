"""docs/field.md "Rehearse on one machine", run as written: the fenced block's commands, one
by one, in an empty directory (a line ending in ``&`` is a background process). Only port
flags are added, so parallel runs do not collide; every process is stopped with SIGTERM at
the end and must exit 0.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.provision.keys_dir import SwarmDir
from tests.helpers.swarm_procs import uavs_seen

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "field.md"
SECTION = "## Rehearse on one machine"
LANDMARKS = {"L0": (12.0, 8.0), "L1": (-6.0, 20.0), "L2": (18.0, -10.0)}

pytestmark = [pytest.mark.slow, pytest.mark.embedded, pytest.mark.timeout(900)]


def doc_commands() -> list[tuple[list[str], bool]]:
    """(argv, in the background) for each command of the section's first fenced block."""
    text = DOC.read_text(encoding="utf-8")
    section = text.split(SECTION, 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```(?:bash)?\n(.*?)```", section, re.S)
    assert block is not None, f"no fenced block under {SECTION!r} in {DOC}"
    out = []
    for line in block.group(1).splitlines():
        words = shlex.split(line, comments=True)
        if not words:
            continue
        background = words[-1] == "&"
        out.append((words[:-1] if background else words, background))
    return out


def consecutive_ports(n: int, kind: int) -> int:
    """A base port such that base .. base+n-1 are all free (TCP or UDP) right now."""
    for _ in range(200):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            base = int(s.getsockname()[1])
        if base + n > 65000:
            continue
        socks = []
        try:
            for p in range(base, base + n):
                sock = socket.socket(socket.AF_INET, kind)
                socks.append(sock)
                sock.bind(("127.0.0.1", p))
            return base
        except OSError:
            continue
        finally:
            for sock in socks:
                sock.close()
    raise AssertionError("no run of free ports")


def with_ports(argv: list[str], router: int, vehicle: int) -> list[str]:
    """The doc's command plus the port flags of this run (nothing else changes)."""
    if argv[1:3] == ["keys", "init"]:
        return [*argv, "--port", str(router), "--vehicle-port", str(vehicle)]
    if argv[1] == "emulator":
        return [*argv, "--port-base", str(vehicle)]
    if argv[1] == "console":
        return [*argv, "--port", "0"]
    return argv


async def uavs_up(keys_dir: Path, uavs: set[str], timeout_s: float) -> bool:
    """What an operator waits for before `mission start`: every UAV's token at the router,
    seen by the read-only observer identity."""
    keys = SwarmDir.open(keys_dir)
    base = keys.mesh("observer")
    cfg = MeshConfig.model_validate(
        {**base.model_dump(), "mode": "client", "listen": [],
         "zenoh_overrides": {"connect/timeout_ms": "30000"}}
    )  # fmt: skip
    return await uavs_seen(cfg, keys.swarm, uavs, timeout_s)


def test_the_rehearsal_in_docs_field_md_flies(tmp_path: Path) -> None:
    commands = doc_commands()
    programs = [argv[1] for argv, _ in commands]
    assert all(argv[0] == "aeroweaver" for argv, _ in commands)
    assert programs == ["keys", "emulator", "router", "daemon", "daemon", "daemon", "console",
                        "mission", "mission"]  # fmt: skip
    keys_dir = tmp_path / commands[0][0][commands[0][0].index("--out") + 1]
    # router + uav0..2 listen on TCP router..router+3; the emulator's vehicle i sends to UDP
    # vehicle+i and listens on vehicle+40+i
    router = consecutive_ports(4, socket.SOCK_STREAM)
    vehicle = consecutive_ports(43, socket.SOCK_DGRAM)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    background: list[tuple[str, subprocess.Popen[bytes]]] = []
    records: list[dict[str, object]] = []
    started = time.monotonic()
    try:
        for i, (argv, bg) in enumerate(commands):
            own = with_ports(argv, router, vehicle)[1:]
            cmd = [sys.executable, "-m", "aeroweaver_edge", *own]
            log = tmp_path / f"{i:02d}-{argv[1]}.log"
            if bg:
                with log.open("wb") as fh:
                    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdin=subprocess.DEVNULL,
                                            stdout=fh, stderr=subprocess.STDOUT)  # fmt: skip
                background.append((log.name, proc))
                continue
            if argv[1] == "mission":
                # an operator starts the mission once the daemons are up (the doc says so)
                assert asyncio.run(uavs_up(keys_dir, {"uav0", "uav1", "uav2"}, 120.0)), tails(
                    tmp_path
                )
            done = subprocess.run(cmd, cwd=tmp_path, env=env, stdin=subprocess.DEVNULL,
                                  capture_output=True, timeout=300)  # fmt: skip
            log.write_bytes(done.stdout + done.stderr)
            assert done.returncode == 0, (argv, log.read_text()[-2000:], tails(tmp_path))
            if argv[1] == "mission":
                out = argv[argv.index("--json") + 1]
                records.append(json.loads((tmp_path / out).read_text()))
        console = next(p for n, p in background if n.endswith("console.log"))
        assert console.poll() is None
        text = (tmp_path / next(n for n, _ in background if n.endswith("console.log"))).read_text()
        assert re.search(r"console: http://127\.0\.0\.1:\d+/ \(swarm 'demo'\)", text), text
    finally:
        for _, proc in background:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        codes = {name: proc.wait(timeout=60) for name, proc in background}
    wall = time.monotonic() - started
    print(f"rehearsal wall time {wall:.1f} s")
    assert codes == {name: 0 for name in codes}, (codes, tails(tmp_path))
    emulator_log = next(n for n in codes if n.endswith("emulator.log"))
    assert len(records) == 2
    for record in records:
        assert record["roster"] == ["uav0", "uav1", "uav2"]
        assert record["not_ready"] == []
        progress = record["progress"]
        assert isinstance(progress, dict)
        assert all(row["reports"] >= 24 for row in progress.values()), progress
        # one landmark each: the three drones covered the three landmarks
        targets = {row["last"] for row in progress.values()}
        assert targets == {f"cover_landmark(target_id={lm})" for lm in LANDMARKS}, progress
        assert record["lost_uavs"] == {}
        assert record["out_of_contact"] == []
        security = record["security"]
        assert isinstance(security, dict)
        assert (security["tls"], security["acl"], security["signed"]) == (True, True, True)
        # one field episode, from the UAVs' own round reports (no world scores it)
        (episode,) = record["episodes"]  # type: ignore[misc]
        assert episode["reason"] == "horizon", episode
        assert episode["rounds"] >= 24, episode
        assert episode["decisions"] >= 3 * 24, episode
        assert set(episode["agent_returns"]) == {"uav0", "uav1", "uav2"}
        assert sum(episode["holds_by_cause"].values()) == episode["holds"]
    ids = [r["mission"]["mission_id"] for r in records]  # type: ignore[index]
    assert len(set(ids)) == 2, ids  # two missions, two ids, on the same daemons
    # and the emulated vehicles were really there (the emulator's own status lines)
    emulator = (tmp_path / emulator_log).read_text()
    for name, (north, east) in LANDMARKS.items():
        assert any(
            abs(float(m.group(1)) - north) < 3.0 and abs(float(m.group(2)) - east) < 3.0
            for m in re.finditer(r"N\s+(-?[\d.]+) E\s+(-?[\d.]+)", emulator)
        ), f"no vehicle reached {name}"


def tails(where: Path) -> dict[str, str]:
    return {p.name: p.read_text(errors="replace")[-600:] for p in sorted(where.glob("*.log"))}
