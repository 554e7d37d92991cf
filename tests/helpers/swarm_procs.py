"""A swarm of real processes on loopback for the service tests: an insecure Zenoh router,
``aeroweaver daemon`` processes, ``aeroweaver mission start`` runs, the MAVLink emulator.
Every process is started here and stopped by ``Procs.stop_all`` (the tests' ``finally``)."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path

from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.contracts.wire import Keys
from aeroweaver_edge.mesh.session import Mesh
from tests.helpers.zenoh_net import free_port

TEXT = "Cover the three landmarks with three drones"
UAVS = ("uav0", "uav1", "uav2")


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "aeroweaver_edge", *args]


class Procs:
    """Processes of one test, each with its own log file in ``root``."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.procs: dict[str, subprocess.Popen[bytes]] = {}

    def start(self, name: str, *args: str, env: Mapping[str, str] | None = None) -> Path:
        log = self.root / f"{name}.log"
        with log.open("ab") as out:
            self.procs[name] = subprocess.Popen(
                cli(*args), stdin=subprocess.DEVNULL, stdout=out, stderr=out,
                env={**os.environ, **(env or {})},
            )  # fmt: skip
        return log

    def log(self, name: str) -> str:
        return (self.root / f"{name}.log").read_text(errors="replace")

    def term(self, name: str, timeout_s: float = 30.0) -> tuple[int, float]:
        """SIGTERM ``name``: (exit status, seconds it took)."""
        p = self.procs[name]
        t0 = time.monotonic()
        p.send_signal(signal.SIGTERM)
        code = p.wait(timeout=timeout_s)
        return code, time.monotonic() - t0

    def stop_all(self) -> None:
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in self.procs.values():
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def router_config(root: Path) -> tuple[Path, str]:
    """An insecure loopback router's zenoh config (``aeroweaver router --insecure``)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    path = root / "router.json5"
    path.write_text(
        f'{{ mode: "router", listen: {{ endpoints: ["{endpoint}"] }}, '
        "scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }\n",
        encoding="utf-8",
    )
    return path, endpoint


def daemon_config(root: Path, uav: str, swarm: str, router: str | None, extra: str = "") -> Path:
    """A scripted daemon, a client of ``router`` (None: its own seed, a peer listening on a
    free port and dialling nobody); sim backend unless ``extra`` says otherwise."""
    path = root / f"{uav}.toml"
    mesh = (
        f'mode = "client"\nlisten = []\nconnect = ["{router}"]'
        if router is not None
        else f'mode = "peer"\nlisten = ["tcp/127.0.0.1:{free_port()}"]\nconnect = []'
    )
    path.write_text(
        f'uav = "{uav}"\nswarm = "{swarm}"\n{extra}\n[mesh]\n{mesh}\n'
        '[agent]\nselector = "scripted"\nbeta = 0.0\n',
        encoding="utf-8",
    )
    return path


async def uavs_seen(cfg: MeshConfig, swarm: str, uavs: set[str], timeout_s: float) -> bool:
    """An observer on ``cfg`` sees every UAV's liveliness token within ``timeout_s``."""
    mesh = await Mesh.open(cfg, node_id="observer")
    seen: set[str] = set()
    try:
        watch = mesh.watch_liveliness(Keys(swarm).alive_uav("*"))
        async with asyncio.timeout(timeout_s):
            async for key, alive in watch:
                (seen.add if alive else seen.discard)(key.rsplit("/", 1)[-1])
                if uavs <= seen:
                    return True
    except TimeoutError:
        return False
    finally:
        await mesh.aclose()
    return False


def wait_for_uavs(router: str, swarm: str, uavs: set[str], timeout_s: float = 60.0) -> bool:
    """An observer sees every UAV's token through the router (the router may be starting)."""
    cfg = MeshConfig(mode="client", listen=[], connect=[router],
                     zenoh_overrides={"connect/timeout_ms": "30000"})  # fmt: skip
    return asyncio.run(uavs_seen(cfg, swarm, uavs, timeout_s))


def wait_until(cond: Callable[[], bool], timeout_s: float, step_s: float = 0.1) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(step_s)
    return cond()


def mission(
    *args: str, timeout_s: float = 180.0, env: Mapping[str, str] | None = None
) -> tuple[int, str, str, float]:
    """``aeroweaver mission start TEXT ARGS...``: (status, stdout, stderr, wall seconds)."""
    t0 = time.monotonic()
    done = subprocess.run(
        cli("mission", "start", TEXT, "--no-llm", *args), capture_output=True, text=True,
        timeout=timeout_s, env={**os.environ, **(env or {})}, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    return done.returncode, done.stdout, done.stderr, time.monotonic() - t0


__all__ = ["TEXT", "UAVS", "Procs", "daemon_config", "mission", "router_config",
           "wait_for_uavs", "wait_until"]  # fmt: skip
