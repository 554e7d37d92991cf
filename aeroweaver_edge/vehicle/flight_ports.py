"""Ports for a daemon with a real flight link (``vehicle.backend`` mavlink or mavsdk).

In the field the clock is the wall clock and perception comes from telemetry and peers'
beacons. With ``vehicle.sim_world`` (``aeroweaver sim --link ...``) the simulated world
still gives the lockstep clock, perception and rewards, while the vehicle flies over the
real link (see ``mirror``).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any

from aeroweaver_edge.contracts.wire import Entity, HeaderFactory, Keys

if TYPE_CHECKING:
    from aeroweaver_edge.config import UavConfig
    from aeroweaver_edge.contracts.ports import DaemonPorts
    from aeroweaver_edge.mesh.session import Mesh


def make_backend(cfg: UavConfig) -> Any:
    """The configured flight backend (not started)."""
    if cfg.vehicle.backend == "mavlink":
        from aeroweaver_edge.vehicle.mavlink.backend import MavlinkVehicle

        return MavlinkVehicle(cfg.vehicle, cfg.safety, cfg.uav)
    if cfg.vehicle.backend == "mavsdk":
        from aeroweaver_edge.vehicle.mavsdk_backend import MavsdkVehicle

        return MavsdkVehicle(cfg.vehicle, cfg.safety, cfg.uav)
    raise ValueError(f"not a flight backend: {cfg.vehicle.backend!r}")


def flight_ports(
    cfg: UavConfig, mesh: Mesh, headers: HeaderFactory
) -> tuple[DaemonPorts, Callable[[], Awaitable[None]], Callable[[], Awaitable[None]]]:
    from aeroweaver_edge.contracts.ports import DaemonPorts

    backend = make_backend(cfg)
    if cfg.vehicle.sim_world:
        from aeroweaver_edge.vehicle.mirror import MirroredVehicle
        from aeroweaver_edge.vehicle.sim import SimLink

        link = SimLink(mesh, Keys(cfg.swarm), cfg.uav, headers)

        async def start() -> None:
            await link.start()
            await backend.start()

        async def stop() -> None:
            try:
                await backend.aclose()
            finally:
                await link.aclose()

        return DaemonPorts(MirroredVehicle(backend, link), link, link, link), start, stop

    from aeroweaver_edge.vehicle.field import FieldPerception, NoRewards, WallClock

    f = cfg.field
    points = [
        Entity(id=p.id, kind=p.kind, pos=(p.north, p.east, -cfg.vehicle.altitude_m))
        for p in f.points
    ]
    perception = FieldPerception(
        backend,
        sensing_radius_m=f.sensing_radius_m,
        points=points,
        beacon_max_age_s=f.beacon_max_age_s,
    )
    clock = WallClock(cfg.round_s, f.round_deadline_s)
    return DaemonPorts(backend, clock, perception, NoRewards()), backend.start, backend.aclose
