"""The seam between the lockstep world runner and emulated autopilots (``sim --link``).

The runner hands each episode's world to the bridge (the emulated autopilots fly its
bodies) and, after collecting a round's SimCommands, asks the bridge to *settle*: wait
until the setpoint each UAV declared has arrived over MAVLink at its emulated autopilot
(float32 on the wire, hence the tolerance). The world then steps with whatever the
autopilots hold, so the returns come from the real bytes; a declaration that never
arrives within ``timeout_s`` is counted as a mismatch and the world flies what arrived.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass

from aeroweaver_edge.contracts.wire import SimCommand, Vec3
from aeroweaver_edge.sim.emulator.host import EmulatorHost
from aeroweaver_edge.world.kinematics import KinematicWorld

log = logging.getLogger(__name__)
TOLERANCE = 1e-4  # m/s: float32 rounding of the MAVLink setpoint is ~1e-6 here


@dataclass
class BridgeStats:
    rounds: int = 0
    mismatches: int = 0  # declared setpoints that never arrived in time
    wait_s_max: float = 0.0


class EmulatorBridge:
    def __init__(self, host: EmulatorHost, timeout_s: float = 5.0) -> None:
        self.host = host
        self.timeout_s = timeout_s
        self.stats = BridgeStats()

    def attach(self, world: KinematicWorld) -> None:
        self.host.attach(world)

    def detach(self) -> None:
        self.host.detach()

    def _arrived(self, uav: str, cmd: SimCommand) -> bool:
        body = self.host.world.body(uav)
        want = (0.0, 0.0) if cmd.held else (cmd.vel[0], cmd.vel[1])
        return abs(body.sp_n - want[0]) <= TOLERANCE and abs(body.sp_e - want[1]) <= TOLERANCE

    async def settle(
        self, commands: Mapping[str, SimCommand], uavs: list[str]
    ) -> dict[str, Vec3 | None]:
        """Wait for the declared setpoints; return orders for UAVs without a command (hold)."""
        started = time.monotonic()
        pending = {u: c for u, c in commands.items() if u in self.host.ids}
        while pending:
            pending = {u: c for u, c in pending.items() if not self._arrived(u, c)}
            if not pending:
                break
            if time.monotonic() - started > self.timeout_s:
                self.stats.mismatches += len(pending)
                for u, c in sorted(pending.items()):
                    b, ap = self.host.world.body(u), self.host.vehicle(u)
                    log.warning(
                        "%s: declared %s never reached the autopilot (it holds %.3f, %.3f in %s)",
                        u, "hold" if c.held else f"({c.vel[0]:.3f}, {c.vel[1]:.3f})",
                        b.sp_n, b.sp_e, ap.mode,
                    )  # fmt: skip
                break
            await asyncio.sleep(0.002)
        self.stats.rounds += 1
        self.stats.wait_s_max = max(self.stats.wait_s_max, time.monotonic() - started)
        return {u: None for u in uavs if u not in commands}
