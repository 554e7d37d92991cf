"""The world side of a simulated swarm: lockstep rounds over Zenoh.

Each round the runner sends every present UAV its frozen perception, waits for each UAV's
command until the deadline (the world stays frozen meanwhile), applies them (a missing or
held command holds that UAV), advances 0.5 s, scores the round and sends the rewards. A UAV
whose liveliness token disappears is marked absent and holds for the rest of the run.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import defaultdict
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np

from aeroweaver_edge.config import SimConfig
from aeroweaver_edge.lifecycle import cancel_all
from aeroweaver_edge.sim.episode import Episode, EpisodeResult, RoundResult
from aeroweaver_edge.sim.tasks.base import Task
from aeroweaver_edge.wire import (
    HeaderFactory,
    Keys,
    MsgRef,
    SimCommand,
    SimEpisode,
    SimPerception,
    SimReward,
    Vec3,
    last_chunk,
)

if TYPE_CHECKING:
    from aeroweaver_edge.mesh import Mesh
    from aeroweaver_edge.sim.emulator.bridge import EmulatorBridge

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RoundLog:
    episode: int
    round: int  # 0-based decision round
    result: RoundResult
    commands: dict[str, SimCommand]
    missed: tuple[str, ...]  # present UAVs whose command did not arrive in time
    absent: tuple[str, ...]
    wait_s: float


@dataclass
class RunnerStats:
    commands: int = 0
    deadline_misses: int = 0
    rejected_commands: int = 0
    lost: dict[str, tuple[int, int]] = field(default_factory=dict)  # uav -> (episode, round) lost


class WorldRunner:
    def __init__(
        self,
        mesh: Mesh,
        swarm: str,
        task: Task,
        cfg: SimConfig,
        *,
        on_round: Callable[[RoundLog], Awaitable[None]] | None = None,
        vehicles: EmulatorBridge | None = None,
    ) -> None:
        self.mesh = mesh
        # flight link (sim --link mavlink|mavsdk): emulated autopilots fly the bodies
        self.vehicles = vehicles
        self.keys = Keys(swarm)
        self.task = task
        self.cfg = cfg
        self.headers = HeaderFactory("world")
        self.stats = RunnerStats()
        self.alive: set[str] = set()
        self._on_round = on_round
        self._commands: dict[tuple[int, int], dict[str, SimCommand]] = defaultdict(dict)
        self._changed = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._where: tuple[int, int] = (-1, -1)
        self._finished = False

    async def start(self) -> None:
        self._tasks = [
            asyncio.create_task(self._pump_commands(), name="world-commands"),
            asyncio.create_task(self._pump_liveliness(), name="world-liveliness"),
        ]

    async def aclose(self) -> None:
        await cancel_all(self._tasks)

    async def _pump_commands(self) -> None:
        async for key, cmd in self.mesh.subscribe(self.keys.sim_command("*"), SimCommand):
            if last_chunk(key) != cmd.uav or cmd.h.sender != cmd.uav:
                self.stats.rejected_commands += 1  # a UAV may only command its own body
                continue
            if (cmd.episode, cmd.round) != self._where:
                self.stats.rejected_commands += 1  # late, early or foreign: never buffered
                continue
            self._commands[(cmd.episode, cmd.round)].setdefault(cmd.uav, cmd)
            self._changed.set()

    async def _pump_liveliness(self) -> None:
        async for key, alive in self.mesh.watch_liveliness(self.keys.alive_uav("*")):
            uav = last_chunk(key)
            if alive:
                self.alive.add(uav)
            elif uav in self.alive:
                self.alive.discard(uav)
                if self._finished:
                    continue  # daemons leaving after the run ended were not lost
                self.stats.lost.setdefault(uav, self._where)
                log.warning("%s left the swarm at episode %d round %d; it holds", uav, *self._where)
            self._changed.set()

    async def wait_alive(self, uavs: list[str], timeout_s: float) -> set[str]:
        """Wait until every UAV's liveliness token is seen; returns the missing ones."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                while not set(uavs) <= self.alive:
                    self._changed.clear()
                    await self._changed.wait()
        return set(uavs) - self.alive

    def _publish_episode(
        self, episode: int, phase: Literal["start", "end", "shutdown"], reason: str = ""
    ) -> None:
        self.mesh.put(
            self.keys.sim_episode,
            SimEpisode(
                h=self.headers.next(),
                episode=episode,
                task=self.task.name,
                phase=phase,
                reason=reason,
            ),
            block=True,
        )

    async def _collect(
        self, key: tuple[int, int], expected: set[str]
    ) -> tuple[dict[str, SimCommand], float]:
        started = time.monotonic()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(self.cfg.deadline_s):
                while not (expected & self.alive) <= set(self._commands[key]):
                    self._changed.clear()
                    await self._changed.wait()
        return self._commands.pop(key, {}), time.monotonic() - started

    async def run_episode(self, episode: int) -> EpisodeResult:
        rng = np.random.default_rng(self.cfg.seed + episode)
        world = self.task.build_world(rng, self.cfg)
        if self.vehicles is not None:  # flight link: the emulated autopilots fly this world
            self.vehicles.attach(world)
        ep = Episode(self.task, world, self.cfg.max_rounds)
        self._publish_episode(episode, "start")
        inbox: dict[str, list[MsgRef]] = defaultdict(list)
        while not ep.done:
            rnd = ep.round
            self._where = (episode, rnd)
            present = [u for u in world.uav_ids if u in self.alive]
            for uav in world.uav_ids:
                if uav not in self.alive:
                    world.mark_absent(uav)
            for uav in present:
                body = world.body(uav)
                self.mesh.put(
                    self.keys.sim_perception(uav),
                    SimPerception(
                        h=self.headers.next(),
                        uav=uav,
                        episode=episode,
                        round=rnd,
                        deadline_s=self.cfg.deadline_s,
                        pos=body.pos,
                        vel=body.vel,
                        entities=self.task.visible(world, uav),
                        expected_inbox=inbox.pop(uav, []),
                    ),
                    block=True,
                )
            inbox.clear()
            commands, waited = await self._collect((episode, rnd), set(present))
            missed = tuple(u for u in present if u not in commands)
            self.stats.deadline_misses += len(missed)
            self.stats.commands += len(commands)
            orders: dict[str, Vec3 | None] = {u: None for u in world.uav_ids}
            for uav, cmd in commands.items():
                if uav in orders:
                    orders[uav] = None if cmd.held else cmd.vel
                for ref in cmd.sent:
                    if ref.to:
                        inbox[ref.to].append(ref)
            if self.vehicles is not None:
                # flight link: the bodies move as the autopilots were told over MAVLink; wait
                # until each declared setpoint has arrived, then hold only the silent UAVs.
                orders = await self.vehicles.settle(commands, world.uav_ids)
            ep.apply(orders)
            res = ep.advance()
            for uav in world.uav_ids:
                self.mesh.put(
                    self.keys.sim_reward(uav),
                    SimReward(
                        h=self.headers.next(),
                        uav=uav,
                        episode=episode,
                        round=rnd,
                        reward=res.rewards.get(uav, 0.0),
                        done=res.done,
                        reason=res.reason or "",
                    ),
                    block=True,
                )
            if self._on_round is not None:
                absent = tuple(u for u in world.uav_ids if u not in self.alive)
                await self._on_round(RoundLog(episode, rnd, res, commands, missed, absent, waited))
        result = ep.result()
        self._publish_episode(episode, "end", result.reason)
        return result

    def shutdown(self) -> None:
        """Tell every daemon the run is over (they leave their round loop and exit)."""
        self._finished = True
        self._publish_episode(-1, "shutdown")
