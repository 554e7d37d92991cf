"""A flying daemon's vehicle half, as a process of its own, for kill tests: the real
``MavlinkVehicle`` and ``FlightPhases`` connect (preflight sets the companion-loss
failsafe), arm, take off, enter the mission phase and stream a setpoint. It prints
``flying`` once in the mission phase and then keeps streaming until it is killed.

    python -m tests.helpers.flier URL [ALTITUDE_M] [VELOCITY_N]
"""

from __future__ import annotations

import asyncio
import logging
import sys

from aeroweaver_edge.config import SafetyConfig, VehicleConfig
from aeroweaver_edge.daemon.flight_phases import FlightPhases
from aeroweaver_edge.vehicle.mavlink.backend import MavlinkVehicle


async def main(url: str, altitude_m: float, north: float) -> int:
    cfg = VehicleConfig(backend="mavlink", url=url, connect_timeout_s=60.0, takeoff_timeout_s=120.0)
    v = MavlinkVehicle(cfg, SafetyConfig(), "uav0")
    await v.start()
    phases = FlightPhases(v, uav="uav0", altitude_m=altitude_m)
    if not await phases.launch():
        print(f"refused: {phases.stats.transitions[-1][2]}", flush=True)
        await v.aclose()
        return 2
    print("flying", flush=True)
    while True:
        await phases.set_velocity(north, 0.0, 0.0)  # renews the lease: a live daemon
        await asyncio.sleep(0.5)


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    args = sys.argv[1:]
    sys.exit(
        asyncio.run(
            main(
                args[0],
                float(args[1]) if len(args) > 1 else 5.0,
                float(args[2]) if len(args) > 2 else 0.0,
            )
        )
    )
