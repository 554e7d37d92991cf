"""The simulator backend: Vehicle, Clock, Perception and RewardSource ports served by the
kinematic world over Zenoh, in lockstep.

The world sends each UAV its frozen perception (the round trigger, what it senses and its
private facts); the UAV answers with one gated velocity setpoint, the list of peer messages
it sent (so the world can tell each recipient what to wait for next round) and its guess,
if a skill recorded one. A UAV that misses the world's deadline holds.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Sequence
from typing import TYPE_CHECKING

from aeroweaver_edge.lifecycle import cancel_all
from aeroweaver_edge.observation import VehicleState
from aeroweaver_edge.ports import Health, Percept, RewardEvent, RoundTick
from aeroweaver_edge.wire import (
    HeaderFactory,
    Keys,
    MsgRef,
    SimCommand,
    SimEpisode,
    SimPerception,
    SimReward,
    Vec3,
)

if TYPE_CHECKING:
    from aeroweaver_edge.mesh import Mesh, Subscription

ZERO: Vec3 = (0.0, 0.0, 0.0)


class SimLink:
    """One UAV's link to the simulated world. Serves four ports from one subscription set."""

    def __init__(
        self, mesh: Mesh, keys: Keys, uav: str, headers: HeaderFactory, reward_wait_s: float = 2.0
    ) -> None:
        self._mesh = mesh
        self._keys = keys
        self.uav = uav
        self._headers = headers
        self._reward_wait_s = reward_wait_s
        self._ticks: asyncio.Queue[SimPerception | None] = asyncio.Queue()
        self._rewards: list[RewardEvent] = []
        self._reward_seen: set[tuple[int, int]] = set()
        self._reward_cond = asyncio.Condition()
        self._current: SimPerception | None = None
        self._last_played: tuple[int, int] | None = None
        self._setpoint: Vec3 = ZERO
        self._held = True
        # Flight phases: the simulated airframe starts disarmed on the ground and goes
        # through arm and take-off like a real one. The world flies it at the fixed flight
        # level either way (take-off happens before the first round), so returns are as before.
        self.armed = False
        self.in_air = False
        self._tasks: list[asyncio.Task[None]] = []

    async def start(self) -> None:
        per = self._mesh.subscribe(self._keys.sim_perception(self.uav), SimPerception)
        rew = self._mesh.subscribe(self._keys.sim_reward(self.uav), SimReward)
        epi = self._mesh.subscribe(self._keys.sim_episode, SimEpisode)
        self._tasks = [
            asyncio.create_task(self._pump_perception(per), name=f"{self.uav}-sim-perception"),
            asyncio.create_task(self._pump_rewards(rew), name=f"{self.uav}-sim-rewards"),
            asyncio.create_task(self._pump_episodes(epi), name=f"{self.uav}-sim-episodes"),
        ]

    async def aclose(self) -> None:
        await cancel_all(self._tasks)

    async def _pump_perception(self, sub: Subscription[SimPerception]) -> None:
        async for _key, msg in sub:
            if msg.uav == self.uav:
                await self._ticks.put(msg)

    async def _pump_rewards(self, sub: Subscription[SimReward]) -> None:
        async for _key, msg in sub:
            if msg.uav != self.uav or (msg.episode, msg.round) in self._reward_seen:
                continue
            async with self._reward_cond:
                self._reward_seen.add((msg.episode, msg.round))
                self._rewards.append(
                    RewardEvent(msg.episode, msg.round, msg.reward, msg.done, "sim")
                )
                self._reward_cond.notify_all()

    async def _pump_episodes(self, sub: Subscription[SimEpisode]) -> None:
        async for _key, msg in sub:
            if msg.phase == "shutdown":
                await self._ticks.put(None)

    async def _await_reward(self, key: tuple[int, int]) -> None:
        """Lockstep: a round's reward reaches the agent before its next round starts."""
        async with self._reward_cond:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(self._reward_wait_s):
                    await self._reward_cond.wait_for(lambda: key in self._reward_seen)

    # Clock
    async def next_round(self) -> RoundTick | None:
        msg = await self._ticks.get()
        if self._last_played is not None:
            await self._await_reward(self._last_played)
        if msg is None:
            return None
        self._current = msg
        self._setpoint, self._held = ZERO, True
        return RoundTick(msg.episode, msg.round, msg.deadline_s, tuple(msg.expected_inbox))

    async def finish(
        self, tick: RoundTick, *, sent: Sequence[MsgRef], guess: str | None = None
    ) -> None:
        self._last_played = (tick.episode, tick.round)
        self._mesh.put(
            self._keys.sim_command(self.uav),
            SimCommand(
                h=self._headers.next(),
                uav=self.uav,
                episode=tick.episode,
                round=tick.round,
                vel=self._setpoint,
                held=self._held,
                sent=list(sent),
                guess=guess,
            ),
            block=True,
        )

    async def settle(self, tick: RoundTick) -> None:
        """Wait (bounded) for ``tick``'s reward: the daemon takes it at the end of the round,
        so an episode's last reward is absorbed before the world starts the next one."""
        await self._await_reward((tick.episode, tick.round))

    # Perception
    async def sense(self, tick: RoundTick) -> Percept:
        msg = self._require()
        return Percept(
            VehicleState(msg.pos, msg.vel, self.armed, self.in_air), msg.entities, msg.facts
        )

    # RewardSource
    def drain(self) -> list[RewardEvent]:
        out, self._rewards = self._rewards, []
        return out

    # Vehicle: arm and take-off change only the phase flags (the world is planar).
    def _require(self) -> SimPerception:
        if self._current is None:
            raise RuntimeError(f"{self.uav}: no perception from the simulator yet")
        return self._current

    async def state(self) -> VehicleState:
        msg = self._require()
        return VehicleState(msg.pos, msg.vel, self.armed, self.in_air)

    async def arm(self) -> None:
        self.armed = True

    async def takeoff(self, altitude_m: float) -> None:
        if not self.armed:
            raise RuntimeError(f"{self.uav}: take-off while disarmed")
        self.in_air = True

    async def set_velocity(self, north: float, east: float, down: float) -> None:
        if self.in_air:
            self._setpoint, self._held = (north, east, down), False

    async def goto(self, north: float, east: float, down: float) -> None:
        raise NotImplementedError("the kinematic simulator flies velocity setpoints only")

    async def hold(self) -> None:
        self._setpoint, self._held = ZERO, True

    async def land(self) -> None:
        await self.hold()
        self.in_air = self.armed = False

    async def return_home(self) -> None:
        await self.land()

    async def health(self) -> Health:
        return Health(ok=self._current is not None, detail="sim")
