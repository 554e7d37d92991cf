"""Helpers for tests that fly real MAVLink bytes over loopback UDP: an emulator plus one
``mavlink`` backend per vehicle, on free ports."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import time
from collections.abc import AsyncIterator, Callable, Sequence
from typing import Any

from aeroweaver_edge.config import SafetyConfig, VehicleConfig
from aeroweaver_edge.sim.emulator.autopilot import Faults
from aeroweaver_edge.sim.emulator.host import EmulatorHost, EmulatorOptions
from aeroweaver_edge.vehicle.mavlink.backend import MavlinkVehicle


def free_udp_ports(n: int) -> list[int]:
    socks = []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind(("127.0.0.1", 0))
            socks.append(s)
        return [int(s.getsockname()[1]) for s in socks]
    finally:
        for s in socks:
            s.close()


FAST = {
    "link_timeout_s": 1.0,
    "command_timeout_s": 0.2,
    "connect_timeout_s": 5.0,
}


def vehicle_config(port: int, **over: Any) -> VehicleConfig:
    fields: dict[str, Any] = {"backend": "mavlink", "url": f"udpin://127.0.0.1:{port}", **FAST}
    fields.update(over)
    return VehicleConfig(**fields)


@contextlib.asynccontextmanager
async def emulated(
    n: int = 1,
    *,
    personality: str = "px4",
    faults: Sequence[Faults] | None = None,
    time_scale: float = 4.0,
    params: dict[str, float] | None = None,
    signing_keys: Sequence[bytes | None] = (),
    vehicle: dict[str, Any] | None = None,
    safety: SafetyConfig | None = None,
    start: bool = True,
) -> AsyncIterator[tuple[EmulatorHost, list[MavlinkVehicle]]]:
    """``n`` emulated vehicles and a started backend for each (udpin on a free port)."""
    ports = free_udp_ports(n)
    opts = EmulatorOptions(
        uavs=n,
        personality=personality,
        local_base=0,
        remote_ports=ports,
        time_scale=time_scale,
        params=params or {},
        signing_keys=signing_keys,
    )
    host = EmulatorHost(opts, faults=faults)
    await host.start()
    backends = [
        MavlinkVehicle(vehicle_config(p, **(vehicle or {})), safety or SafetyConfig(), f"uav{i}")
        for i, p in enumerate(ports)
    ]
    try:
        if start:
            await asyncio.gather(*(b.start() for b in backends))
        yield host, backends
    finally:
        for b in backends:
            await b.aclose()
        await host.aclose()


async def until(cond: Callable[[], bool], timeout_s: float = 5.0, what: str = "condition") -> float:
    """Wait (bounded) until ``cond()``; returns the seconds it took, fails on timeout."""
    started = time.monotonic()
    while not cond():
        if time.monotonic() - started > timeout_s:
            raise AssertionError(f"{what} not reached within {timeout_s} s")
        await asyncio.sleep(0.01)
    return time.monotonic() - started


class ThreadedEmulator:
    """An emulator on its own thread and event loop, so it keeps ticking (and its
    failsafes keep firing) while the test's loop is deliberately blocked."""

    def __init__(self, opts: EmulatorOptions, faults: Sequence[Faults] | None = None) -> None:
        import threading

        self.opts = opts
        self._faults = faults
        self.host: EmulatorHost | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=self._main, name="emulator", daemon=True)

    def _main(self) -> None:
        async def run() -> None:
            self._loop = asyncio.get_running_loop()
            self._stop = asyncio.Event()
            self.host = EmulatorHost(self.opts, faults=self._faults)
            await self.host.start()
            self._ready.set()
            try:
                await self._stop.wait()
            finally:
                await self.host.aclose()

        asyncio.run(run())

    def __enter__(self) -> EmulatorHost:
        self._thread.start()
        if not self._ready.wait(10):
            raise RuntimeError("emulator thread did not start")
        assert self.host is not None
        return self.host

    def __exit__(self, *exc: object) -> None:
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(10)
