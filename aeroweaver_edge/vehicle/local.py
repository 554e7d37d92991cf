"""An in-process vehicle: the Vehicle and Perception ports served straight from a kinematic
world and its task, without a network.

The same physics and the same perception rule as the simulated swarm (the task's ``visible``
and ``private_facts``), for a daemon round driven in this process: unit tests of
``decision_round`` with the in-memory peer channel, and network-free benchmarks. Commands
set the body's setpoint in the world at once; the caller advances the world.
"""

from __future__ import annotations

from aeroweaver_edge.contracts.observation import VehicleState
from aeroweaver_edge.contracts.ports import Health, Percept, RoundTick
from aeroweaver_edge.tasks.base import TaskDefinition
from aeroweaver_edge.world.kinematics import KinematicWorld


class LocalBody:
    """One UAV's body in an in-process world (``Vehicle`` and ``Perception``)."""

    def __init__(self, world: KinematicWorld, uav: str, task: TaskDefinition | None = None) -> None:
        world.body(uav)  # fail early on an unknown id
        self.world = world
        self.uav = uav
        self.task = task
        self.held = True

    async def sense(self, tick: RoundTick) -> Percept:
        body = self.world.body(self.uav)
        if self.task is None:
            return Percept(VehicleState(body.pos, body.vel), self.world.sense(self.uav))
        return Percept(
            VehicleState(body.pos, body.vel),
            self.task.visible(self.world, self.uav),
            self.task.private_facts(self.world, self.uav),
        )

    async def state(self) -> VehicleState:
        body = self.world.body(self.uav)
        return VehicleState(body.pos, body.vel)

    async def arm(self) -> None:
        return None

    async def takeoff(self, altitude_m: float) -> None:
        return None

    async def set_velocity(self, north: float, east: float, down: float) -> None:
        self.held = not self.world.set_velocity(self.uav, (north, east, down))

    async def goto(self, north: float, east: float, down: float) -> None:
        raise NotImplementedError("the kinematic world flies velocity setpoints only")

    async def hold(self) -> None:
        self.world.hold(self.uav)
        self.held = True

    async def land(self) -> None:
        await self.hold()

    async def return_home(self) -> None:
        await self.hold()

    async def health(self) -> Health:
        return Health(ok=not self.world.body(self.uav).absent, detail="local")


__all__ = ["LocalBody"]
