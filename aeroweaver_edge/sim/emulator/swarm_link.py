"""``aeroweaver sim --link mavlink|mavsdk``: emulated autopilots for a simulated swarm.

Builds episode 0's world ahead of the runner (the same seeded layout), so every vehicle
sits on the ground at its spawn point, arms and takes off there; then the runner attaches
each episode's world through the bridge. Vehicle i is system id i+1; each daemon listens
on its own free UDP port (``udpin``), which its emulated autopilot sends to.
"""

from __future__ import annotations

import contextlib
from collections import Counter
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from aeroweaver_edge.config import SimConfig, VehicleConfig
from aeroweaver_edge.contracts.endpoints import UdpUrl
from aeroweaver_edge.sim.emulator.bridge import EmulatorBridge
from aeroweaver_edge.sim.emulator.host import EmulatorHost, EmulatorOptions
from aeroweaver_edge.tasks.base import TaskDefinition
from aeroweaver_edge.vehicle.mavlink.commands import command_name
from aeroweaver_edge.vehicle.mavlink.udp import UdpEndpoint

TIME_SCALE = 5.0  # take-off and landing run 5x faster than real time (physics is lockstep)


async def _free_udp_ports(n: int) -> list[int]:
    eps = [
        await UdpEndpoint.open(UdpUrl("udpin", "127.0.0.1", 0), lambda d, a: None) for _ in range(n)
    ]
    try:
        return [ep.local_port for ep in eps]
    finally:
        for ep in eps:
            ep.close()


@dataclass(frozen=True)
class LinkedSwarm:
    bridge: EmulatorBridge
    vehicles: dict[str, VehicleConfig]  # per UAV: the daemon's vehicle section

    def report(self, link: str) -> dict[str, Any]:
        """What crossed the link, per vehicle (for the run summary)."""
        host = self.bridge.host
        out: dict[str, Any] = {
            "link": link,
            "personality": host.opts.personality,
            "settle_rounds": self.bridge.stats.rounds,
            "settle_mismatches": self.bridge.stats.mismatches,
            "settle_wait_s_max": round(self.bridge.stats.wait_s_max, 4),
            "vehicles": {},
        }
        for ap in host.vehicles:
            out["vehicles"][ap.uav] = {
                "sysid": ap.sysid,
                "commands": Counter(command_name(r.command) for r in ap.log if r.executed),
                "setpoints": ap.setpoints,
                "modes": [t for _at, t in ap.events if t.startswith("mode")],
                "failsafes": [t for _at, t in ap.events if "loss" in t or "breach" in t],
            }
        return out


@contextlib.asynccontextmanager
async def emulated_swarm(
    link: str, task: TaskDefinition, cfg: SimConfig, personality: str = "px4"
) -> AsyncIterator[LinkedSwarm]:
    uavs = task.uav_ids
    world = task.build_world(np.random.default_rng(cfg.seed + 0), cfg)
    opts = EmulatorOptions(
        uavs=len(uavs),
        personality=personality,
        local_base=0,
        remote_ports=[9] * len(uavs),  # discard until the daemons' ports are chosen
        time_scale=TIME_SCALE,
        seed=cfg.seed,
    )
    host = EmulatorHost(opts, world=world, uav_ids=uavs)
    await host.start()
    try:
        ports = await _free_udp_ports(len(uavs))
        for i, port in enumerate(ports):
            host.retarget(i, port)
        vehicles = {
            u: VehicleConfig(
                backend="mavlink" if link == "mavlink" else "mavsdk",
                url=f"udpin://127.0.0.1:{port}",
                sysid=i + 1,
                personality=personality if link == "mavlink" else "auto",
                altitude_m=cfg.altitude_m,
                sim_world=True,
                # Lockstep: between its rounds a UAV waits for the (frozen) world, not for
                # its agent; the world's round deadline bounds that wait, so the lease does.
                lease_s=cfg.deadline_s + 5.0,
            )
            for i, (u, port) in enumerate(zip(uavs, ports, strict=True))
        }
        yield LinkedSwarm(EmulatorBridge(host), vehicles)
    finally:
        await host.aclose()
