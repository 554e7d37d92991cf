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
from aeroweaver_edge.sim.emulator.thread import ThreadedEmulator
from aeroweaver_edge.vehicle.mavlink.backend import MavlinkVehicle

__all__ = ["FAST", "ThreadedEmulator", "emulated", "free_udp_ports", "until", "vehicle_config"]


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
    opts = EmulatorOptions(
        uavs=n,
        personality=personality,
        local_base=0,
        remote_ports=[9] * n,
        time_scale=time_scale,
        params=params or {},
        signing_keys=signing_keys,
    )
    host = EmulatorHost(opts, faults=faults)
    await host.start()
    backends = [
        MavlinkVehicle(vehicle_config(0, **(vehicle or {})), safety or SafetyConfig(), f"uav{i}")
        for i in range(n)
    ]
    try:
        for i, b in enumerate(backends):
            await b.link.open()  # bound first: the emulator sends to a port that is ours
            host.retarget(i, b.link.local_port)
            b.cfg = b.cfg.model_copy(update={"url": f"udpin://127.0.0.1:{b.link.local_port}"})
        if start:
            await asyncio.gather(*(b.start() for b in backends))
        yield host, backends
    finally:
        for b in backends:
            await b.aclose()
        await host.aclose()


async def stop_within(task: asyncio.Task[object], timeout_s: float, what: str) -> None:
    """Cancel ``task`` and wait (bounded) for it to finish: a shutdown that hangs fails
    here by name instead of running into the test's overall timeout."""
    task.cancel()
    done, _ = await asyncio.wait({task}, timeout=timeout_s)
    if not done:
        raise AssertionError(f"{what} did not stop within {timeout_s:g} s of its cancellation")
    if not task.cancelled() and task.exception() is not None:
        raise task.exception()  # type: ignore[misc]


async def until(cond: Callable[[], bool], timeout_s: float = 5.0, what: str = "condition") -> float:
    """Wait (bounded) until ``cond()``; returns the seconds it took, fails on timeout."""
    started = time.monotonic()
    while not cond():
        if time.monotonic() - started > timeout_s:
            raise AssertionError(f"{what} not reached within {timeout_s} s")
        await asyncio.sleep(0.01)
    return time.monotonic() - started
