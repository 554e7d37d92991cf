"""What a UAV knows at the start of a round, frozen for the whole decision."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from aeroweaver_edge.contracts.wire import Entity, InboxMessage, Vec3


def distance(a: Vec3, b: Vec3) -> float:
    return math.dist(a, b)


def horizontal_distance(a: Vec3, b: Vec3) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


@dataclass(frozen=True)
class VehicleState:
    pos: Vec3
    vel: Vec3
    armed: bool = True
    in_air: bool = True


@dataclass(frozen=True)
class MissionView:
    """The UAV's share of the mission: what the Commander assigned to it."""

    mission_id: str
    task: str
    text: str
    role: str
    local_goal: str
    skills: tuple[str, ...]
    constraints: tuple[str, ...] = ()


@dataclass(frozen=True)
class Observation:
    """Frozen for a round. ``facts`` are this UAV's private facts from its Perception port
    (the goal landmark, symbol and key, cargo, its own formation slot: only what its role
    may know, fresh every round). ``memo`` is what this UAV's own skills recorded in earlier
    rounds (e.g. its last guess); it never comes from outside."""

    uav: str
    episode: int
    round: int
    own: VehicleState
    entities: tuple[Entity, ...] = ()
    messages: tuple[InboxMessage, ...] = ()
    memo: dict[str, str] = field(default_factory=dict)
    facts: Mapping[str, str] = field(default_factory=dict)

    def of_kind(self, kind: str) -> list[Entity]:
        return [e for e in self.entities if e.kind == kind]

    def entity(self, entity_id: str) -> Entity | None:
        return next((e for e in self.entities if e.id == entity_id), None)

    def peers(self) -> list[Entity]:
        return [e for e in self.entities if e.kind == "uav"]
