"""Coverage (mpe2 ``simple_spread``): searchers spread out to cover three landmarks.

Layout (authors' substrate, notes/mpe-tasks.md), north/east metres:

* landmarks ``L0..L2`` at (-28, 24), (4, 34), (32, 20), all shifted by ONE seeded group
  offset drawn uniformly in ±10 m per axis (the group keeps its shape);
* UAV ``i`` at (-38 + 14 i, -34 ± 5) plus seeded ±4 m jitter per axis. The note leaves the
  ±5 unspecified; we alternate it, +5 for even i and -5 for odd i, which staggers
  neighbours 10 m apart in east so no two spawn closer than ~11 m. Past 8 UAVs the row
  would leave the arena (north 74 m), so UAV i >= 8 starts a second row 14 m further
  east (column i % 8); for N <= 8 this is exactly the authors' formula.

Random draws, in order: the landmark offset (2 values), then the UAV jitter (2 per UAV).

Completion: every landmark has a UAV within 3 m (horizontal, inclusive), held for 3
consecutive rounds; horizon 24 rounds. Rewards: ``simple_spread`` with ρ = 0.5 at 70 m per
MPE unit. With N != 3 UAVs we keep the authors' 3 landmarks (mpe2 would use N landmarks),
so returns for N != 3 are not comparable with native ``simple_spread_v3(N)``.
"""

from __future__ import annotations

import math
from typing import ClassVar, Final

import numpy as np

from aeroweaver_edge.sim.rewards.mpe import SpreadRewards
from aeroweaver_edge.sim.tasks.base import Metrics, Task, uav_id
from aeroweaver_edge.sim.world import KinematicWorld
from aeroweaver_edge.wire import Entity, Vec3

LANDMARKS_NE: Final = ((-28.0, 24.0), (4.0, 34.0), (32.0, 20.0))
LANDMARK_OFFSET_M: Final = 10.0
SPAWN_JITTER_M: Final = 4.0
COVER_RADIUS_M: Final = 3.0
ROW_LENGTH: Final = 8  # UAVs per spawn row that stay inside the 140 m arena


def spawn_base(i: int) -> tuple[float, float]:
    """Un-jittered spawn point of UAV ``i`` (north, east)."""
    col, row = i % ROW_LENGTH, i // ROW_LENGTH
    stagger = 5.0 if i % 2 == 0 else -5.0
    return -38.0 + 14.0 * col, -34.0 + stagger + 14.0 * row


def landmark_id(index: int) -> str:
    return f"L{index}"


class CoverageTask(Task):
    name: ClassVar[str] = "coverage"
    stable_rounds_needed: ClassVar[int] = 3
    default_max_rounds: ClassVar[int] = 24
    role: ClassVar[str] = "searcher"

    def __init__(
        self, n_uavs: int = 3, *, altitude_m: float = 5.0, max_rounds: int | None = None
    ) -> None:
        super().__init__(n_uavs, altitude_m=altitude_m, max_rounds=max_rounds)
        self._rewards: SpreadRewards | None = None  # built on first use, once per UAV count
        self.landmark_ids = [landmark_id(k) for k in range(len(LANDMARKS_NE))]

    def _resize(self, n_uavs: int) -> None:
        super()._resize(n_uavs)
        self._rewards = None

    def spawn(self, rng: np.random.Generator, n_uavs: int) -> tuple[list[Vec3], list[Entity]]:
        if n_uavs != self.n_uavs:
            self._resize(n_uavs)
        down = -self.altitude_m
        off_n, off_e = (float(v) for v in rng.uniform(-LANDMARK_OFFSET_M, LANDMARK_OFFSET_M, 2))
        jitter = rng.uniform(-SPAWN_JITTER_M, SPAWN_JITTER_M, (n_uavs, 2))
        landmarks = [
            Entity(id=landmark_id(k), kind="landmark", pos=(n + off_n, e + off_e, down))
            for k, (n, e) in enumerate(LANDMARKS_NE)
        ]
        uavs: list[Vec3] = []
        for i in range(n_uavs):
            n, e = spawn_base(i)
            uavs.append((n + float(jitter[i, 0]), e + float(jitter[i, 1]), down))
        return uavs, landmarks

    def roles(self) -> dict[str, str]:
        return {uav_id(i): self.role for i in range(self.n_uavs)}

    def _landmark_ne(self, world: KinematicWorld) -> list[tuple[float, float]]:
        return [(p[0], p[1]) for p in (world.entity(k).pos for k in self.landmark_ids)]

    def _nearest_m(self, world: KinematicWorld) -> dict[str, float]:
        bodies = [world.body(u) for u in self.uav_ids]
        return {
            lid: min(math.hypot(b.north - n, b.east - e) for b in bodies)
            for lid, (n, e) in zip(self.landmark_ids, self._landmark_ne(world), strict=True)
        }

    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        if self._rewards is None:
            self._rewards = SpreadRewards(self.n_uavs, len(self.landmark_ids), local_ratio=0.5)
        ids = self.uav_ids
        agents = [(b.north, b.east) for b in (world.body(u) for u in ids)]
        values = self._rewards(agents, self._landmark_ne(world))
        return dict(zip(ids, values, strict=True))

    def complete(self, world: KinematicWorld) -> bool:
        return all(d <= COVER_RADIUS_M for d in self._nearest_m(world).values())

    def metrics(self, world: KinematicWorld) -> Metrics:
        nearest = self._nearest_m(world)
        out = super().metrics(world)
        out["covered_landmarks"] = float(sum(d <= COVER_RADIUS_M for d in nearest.values()))
        out.update({f"landmark_min_dist_m.{k}": d for k, d in nearest.items()})
        return out
