"""What every benchmark task provides, so the nine tasks plug into one runner.

A task owns the layout (spawn), the roles, what each UAV may sense, the per-round rewards,
the completion flag and the extra metrics. Physics stays in :mod:`aeroweaver_edge.sim.world`
and the termination rule in :mod:`aeroweaver_edge.sim.episode`, so a task is only the part
that differs between tasks (notes/mpe-tasks.md).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

from aeroweaver_edge.config import SimConfig
from aeroweaver_edge.sim.world import KinematicWorld
from aeroweaver_edge.wire import Entity, Vec3

Metrics = dict[str, float]
"""Flat, JSON-friendly metrics, e.g. ``{"near_collisions": 0, "landmark_min_dist_m.L0": 2.5}``."""


def uav_id(index: int) -> str:
    return f"uav{index}"


class Task(ABC):
    """One benchmark task. Subclasses set the class attributes and the abstract methods.

    The UAV count is fixed per instance because reward adapters build their mpe2 world once
    for that count; :meth:`spawn` may still be called with another count, which re-sizes the
    task (and drops its cached reward model).
    """

    name: ClassVar[str]
    stable_rounds_needed: ClassVar[int] = 3
    """Consecutive complete rounds that end the episode as ``"complete"``."""
    default_max_rounds: ClassVar[int] = 24
    scripted_roles: ClassVar[frozenset[str]] = frozenset()
    """Roles flown by fixed policies; excluded from the controlled-team mean."""

    def __init__(
        self, n_uavs: int = 3, *, altitude_m: float = 5.0, max_rounds: int | None = None
    ) -> None:
        self._check_n(n_uavs)
        if max_rounds is not None and max_rounds < 1:
            raise ValueError(f"max_rounds must be >= 1, got {max_rounds}")
        self.n_uavs = n_uavs
        self.altitude_m = altitude_m
        self.max_rounds = self.default_max_rounds if max_rounds is None else max_rounds

    def _check_n(self, n_uavs: int) -> None:
        if not 1 <= n_uavs <= 10:
            raise ValueError(f"{type(self).__name__}: n_uavs must be 1..10, got {n_uavs}")

    @property
    def uav_ids(self) -> list[str]:
        return [uav_id(i) for i in range(self.n_uavs)]

    def _resize(self, n_uavs: int) -> None:
        """Called by :meth:`spawn` when the count changes; subclasses drop size-bound caches."""
        self._check_n(n_uavs)
        self.n_uavs = n_uavs

    @abstractmethod
    def spawn(self, rng: np.random.Generator, n_uavs: int) -> tuple[list[Vec3], list[Entity]]:
        """Seeded initial layout: UAV positions (index i is ``uav{i}``) and static entities."""

    @abstractmethod
    def roles(self) -> dict[str, str]:
        """Role of every UAV id."""

    def visible(self, world: KinematicWorld, uav: str) -> list[Entity]:
        """What ``uav`` senses this round: entities and peers (kind ``"uav"``) within range."""
        return world.sense(uav)

    @abstractmethod
    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        """Per-UAV reward for the current (post-step) state."""

    @abstractmethod
    def complete(self, world: KinematicWorld) -> bool:
        """The task's success flag for the current state (one round's worth)."""

    def metrics(self, world: KinematicWorld) -> Metrics:
        """Extra per-round metrics; every task reports near collisions (pairs < 2 m)."""
        return {"near_collisions": float(world.near_collisions(2.0))}

    def build_world(
        self, rng: np.random.Generator, config: SimConfig | None = None
    ) -> KinematicWorld:
        """Spawn this task into a fresh world (roles attached to the bodies)."""
        cfg = config or SimConfig(uavs=self.n_uavs, altitude_m=self.altitude_m)
        if cfg.altitude_m != self.altitude_m:
            raise ValueError(
                f"config altitude {cfg.altitude_m} m differs from the task's {self.altitude_m} m"
            )
        world = KinematicWorld.from_config(cfg)
        positions, entities = self.spawn(rng, cfg.uavs)
        roles = self.roles()
        for i, pos in enumerate(positions):
            world.add_uav(uav_id(i), pos, role=roles[uav_id(i)])
        for entity in entities:
            world.add_entity(entity)
        return world
