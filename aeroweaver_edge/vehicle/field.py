"""Clock, Perception and RewardSource for a daemon flying a real vehicle (no simulator).

* ``WallClock``: a round every ``round_s`` on the monotonic clock; rounds that a slow
  decision overran are skipped, never queued.
* ``FieldPerception``: own state from the vehicle's telemetry; peers from their state
  beacons (fresh ones only, judged by *local* receipt time: wall clocks of other UAVs are
  never compared); static points of interest from config; all within the sensing radius.
* ``NoRewards``: the field has no reward signal (experience is still recorded).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable, Mapping, Sequence

from aeroweaver_edge.contracts.ports import Percept, RewardEvent, RoundTick, Vehicle
from aeroweaver_edge.contracts.wire import Entity, MsgRef, StateBeacon


class WallClock:
    def __init__(
        self, round_s: float, deadline_s: float, episode: int = 0, rounds: int | None = None
    ) -> None:
        if not (round_s > 0 and deadline_s > 0):
            raise ValueError("round_s and deadline_s must be > 0")
        self.round_s = round_s
        self.deadline_s = deadline_s
        self.episode = episode
        self.rounds = rounds  # None: run until cancelled
        self.round = -1
        self.skipped = 0
        self._t0: float | None = None

    async def next_round(self) -> RoundTick | None:
        now = time.monotonic()
        if self._t0 is None:
            self._t0 = now
        nxt = self.round + 1
        due = self._t0 + nxt * self.round_s
        if now > due + self.round_s:  # overran: jump to the current slot
            late = int((now - self._t0) / self.round_s)
            self.skipped += late - nxt
            nxt, due = late, self._t0 + late * self.round_s
        if self.rounds is not None and nxt >= self.rounds:
            return None
        if due > now:
            await asyncio.sleep(due - now)
        self.round = nxt
        return RoundTick(self.episode, nxt, self.deadline_s)

    async def finish(
        self, tick: RoundTick, *, sent: Sequence[MsgRef], guess: str | None = None
    ) -> None:
        return None


class FieldPerception:
    def __init__(
        self,
        vehicle: Vehicle,
        *,
        sensing_radius_m: float = 45.0,
        points: Sequence[Entity] = (),
        beacon_max_age_s: float = 3.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.vehicle = vehicle
        self._clock = clock
        self.sensing_radius_m = sensing_radius_m
        self.points = list(points)
        self.beacon_max_age_s = beacon_max_age_s
        self._neighbours: Callable[[], Mapping[str, StateBeacon]] = dict
        self._seen: dict[str, tuple[tuple[int, int], float]] = {}

    def attach(self, neighbours: Callable[[], Mapping[str, StateBeacon]]) -> None:
        """Where peers' latest beacons come from (the daemon's PeerLink)."""
        self._neighbours = neighbours

    def _fresh_peers(self, now: float) -> list[StateBeacon]:
        out = []
        beacons = dict(self._neighbours())
        for uav in list(self._seen):
            if uav not in beacons:
                del self._seen[uav]
        for uav, b in beacons.items():
            key = (b.h.epoch, b.h.seq)
            prev = self._seen.get(uav)
            if prev is None or prev[0] != key:
                self._seen[uav] = (key, now)
            elif now - prev[1] > self.beacon_max_age_s:
                continue
            if all(math.isfinite(v) for v in b.pos):
                out.append(b)
        return out

    async def sense(self, tick: RoundTick) -> Percept:
        own = await self.vehicle.state()
        r = self.sensing_radius_m

        def near(pos: tuple[float, float, float]) -> bool:
            return math.hypot(pos[0] - own.pos[0], pos[1] - own.pos[1]) <= r

        entities = [p for p in self.points if near(p.pos)]
        entities += [
            Entity(id=b.uav, kind="uav", pos=b.pos, vel=b.vel, role=b.role)
            for b in sorted(self._fresh_peers(self._clock()), key=lambda b: b.uav)
            if near(b.pos)
        ]
        return Percept(own, entities)  # no private facts in the field (yet)


class NoRewards:
    def drain(self) -> list[RewardEvent]:
        return []
