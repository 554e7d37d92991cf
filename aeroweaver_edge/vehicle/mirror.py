"""A vehicle flown over a real link whose commands are also declared to the lockstep world.

``aeroweaver sim --link mavlink|mavsdk``: the primary backend sends real MAVLink bytes to
the emulated autopilot (which moves the world's body); the sim link only *declares* the
same command in the round's SimCommand, so the world knows what to wait for before it
steps (it then flies what the emulator received, never the declaration).
"""

from __future__ import annotations

from aeroweaver_edge.contracts.observation import VehicleState
from aeroweaver_edge.contracts.ports import Health, Vehicle
from aeroweaver_edge.contracts.wire import VehicleStatus


class MirroredVehicle:
    def __init__(self, primary: Vehicle, declared: Vehicle) -> None:
        self.primary = primary
        self.declared = declared

    async def state(self) -> VehicleState:
        return await self.primary.state()

    async def health(self) -> Health:
        return await self.primary.health()

    def telemetry(self) -> VehicleStatus | None:
        read = getattr(self.primary, "telemetry", None)
        return read() if read is not None else None

    async def arm(self) -> None:
        await self.primary.arm()
        await self.declared.arm()

    async def takeoff(self, altitude_m: float) -> None:
        await self.primary.takeoff(altitude_m)
        await self.declared.takeoff(altitude_m)

    async def set_velocity(self, north: float, east: float, down: float) -> None:
        await self.primary.set_velocity(north, east, down)
        await self.declared.set_velocity(north, east, down)

    async def goto(self, north: float, east: float, down: float) -> None:
        await self.primary.goto(north, east, down)
        await self.declared.hold()  # the lockstep world cannot declare a position target

    async def hold(self) -> None:
        try:
            await self.primary.hold()
        finally:
            await self.declared.hold()

    async def land(self) -> None:
        try:
            await self.primary.land()
        finally:
            await self.declared.land()

    async def return_home(self) -> None:
        try:
            await self.primary.return_home()
        finally:
            await self.declared.return_home()
