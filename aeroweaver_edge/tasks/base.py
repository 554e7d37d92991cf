"""One task definition per task, like mpe2's ``BaseScenario``: everything that differs
between tasks, in one class, in one module per task.

A ``TaskDefinition`` instance is one task at one swarm size with one role assignment. It
owns the seeded layout (``layout``), the private state of an episode (goal landmark,
symbols, cargo, guesses), what each body senses (``visible``, role sensing radius) and
privately knows (``private_facts``), who hears whom (``spec.reaches``), the world-flown
opponents (``scripted_actions``), the task dynamics after physics (``after_step``), the
mpe2 rewards (``rewards``), the completion flag (``complete``) and the metrics. Its
``SPEC`` (``aeroweaver_edge.tasks.spec``) is what the Commander reads; its ``reference``
policy scores candidates for ``--selector scripted``.

The episode loop (``aeroweaver_edge.sim.episode``) and the networked runner call it; physics
stays in ``aeroweaver_edge.world.kinematics``. The call order of one round is::

    scripted_actions(world, round, inboxes)   # the world's own agents decide on the frozen state
    record_guess(uav, guess)                  # for every command that carries a guess
    world.step()                              # physics: 0.5 s
    after_step(world)                         # pickups, deliveries, visits
    rewards(world); complete(world, round); metrics(world)

Bodies are the controlled UAVs (daemons; ids as given, e.g. ``uav0``) followed by the
scripted ones (``<role><k>``, e.g. ``evader0``).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar, Protocol

from aeroweaver_edge.config import SimConfig
from aeroweaver_edge.contracts.defaults import ALTITUDE_M, COMM_RADIUS_M
from aeroweaver_edge.contracts.wire import Entity, InboxMessage, Vec3
from aeroweaver_edge.tasks.spec import TaskSpec
from aeroweaver_edge.world.kinematics import KinematicWorld

if TYPE_CHECKING:
    import numpy as np

    from aeroweaver_edge.contracts.ports import DecisionRequest

Metrics = dict[str, float]
"""Flat, JSON-friendly metrics, e.g. ``{"near_collisions": 0, "landmark_min_dist_m.L0": 2.5}``."""

NE = tuple[float, float]
"""North, east in metres."""

NEAR_COLLISION_M = 2.0


def uav_id(index: int) -> str:
    return f"uav{index}"


@dataclass(frozen=True)
class Layout:
    """A seeded initial state: every body's position and the static entities."""

    positions: dict[str, NE]
    entities: list[Entity] = field(default_factory=list)


@dataclass(frozen=True)
class Action:
    """What one body does this round: a velocity (``None``: hold) and maybe a guess."""

    vel: Vec3 | None
    guess: str | None = None


HOLD_ACTION = Action(None)


class ReferencePolicy(Protocol):
    """A task's scripted reference policy: a utility per labelled candidate (label -> value),
    from the same request the LLM would see. The scripted selector turns the utilities into
    log-softmax scores, so ``choose`` and the experience correction apply unchanged. Must be
    deterministic and use only what the UAV observes (its observation, facts, messages)."""

    def utilities(self, request: DecisionRequest) -> dict[str, float]: ...


class TaskDefinition(ABC):
    """Base of the nine task definitions; a new task is one subclass in one module."""

    spec: ClassVar[TaskSpec]
    reference: ClassVar[ReferencePolicy]

    def __init__(
        self,
        roles: Mapping[str, str] | int | None = None,
        *,
        max_rounds: int | None = None,
        altitude_m: float = ALTITUDE_M,
    ) -> None:
        spec = self.spec
        if roles is None or isinstance(roles, int):
            n = spec.team_size if roles is None else roles
            if not spec.size_ok(n):
                raise ValueError(f"{spec.name} needs {spec.describe_size()}, got {n}")
            counts = spec.role_counts(n)
            names = [r.name for r in spec.roles for _ in range(counts.get(r.name, 0))]
            assigned = {uav_id(i): role for i, role in enumerate(names)}
        else:
            assigned = dict(roles)
        counts = {r: 0 for r in spec.role_names}
        for uav, role in assigned.items():
            if role not in counts:
                raise ValueError(
                    f"{uav}: {role!r} is not a role of {spec.name} "
                    f"(roles: {', '.join(spec.role_names)})"
                )
            counts[role] += 1
        problem = spec.check_counts(counts)
        if problem is not None:
            raise ValueError(problem)
        if max_rounds is not None and max_rounds < 1:
            raise ValueError(f"max_rounds must be >= 1, got {max_rounds}")
        self.altitude_m = altitude_m
        self.max_rounds = spec.max_rounds if max_rounds is None else max_rounds
        self._roles: dict[str, str] = dict(assigned)
        self._controlled = list(assigned)
        n = len(assigned)
        self._scripted: list[str] = []
        for r in spec.scripted:
            for k in range(spec.scripted_counts(n).get(r.name, 0)):
                sid = f"{r.name}{k}"
                if sid in self._roles:
                    raise ValueError(f"UAV id {sid!r} is reserved for a scripted {r.name}")
                self._roles[sid] = r.name
                self._scripted.append(sid)
        self._index: dict[str, int] = {}
        seen: dict[str, int] = {}
        for body, role in self._roles.items():
            self._index[body] = seen.get(role, 0)
            seen[role] = self._index[body] + 1
        self.setup()

    def setup(self) -> None:  # noqa: B027 - optional hook
        """Per-instance state of a task once its bodies and roles are known (override)."""

    # -- identity ----------------------------------------------------------------------

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def n_uavs(self) -> int:
        """Controlled UAVs (daemons)."""
        return len(self._controlled)

    @property
    def uav_ids(self) -> list[str]:
        """Controlled UAVs, in assignment order."""
        return list(self._controlled)

    @property
    def scripted_ids(self) -> list[str]:
        return list(self._scripted)

    @property
    def body_ids(self) -> list[str]:
        return [*self._controlled, *self._scripted]

    def roles(self) -> dict[str, str]:
        """Role of every body, controlled first."""
        return dict(self._roles)

    def role_of(self, body: str) -> str:
        return self._roles[body]

    def index_in_role(self, body: str) -> int:
        """0 for the first body of its role, 1 for the second, ..."""
        return self._index[body]

    def of_role(self, role: str) -> list[str]:
        return [b for b, r in self._roles.items() if r == role]

    def is_scripted(self, body: str) -> bool:
        return body in self._scripted

    @property
    def scripted_roles(self) -> frozenset[str]:
        return frozenset(self.spec.scripted_names)

    @property
    def stable_rounds_needed(self) -> int:
        return self.spec.stable_rounds

    @property
    def scripted_listeners(self) -> list[str]:
        """World-flown bodies that receive peer messages (they get an inbox on the mesh)."""
        return [b for b in self._scripted if self.spec.role(self.role_of(b)).listens]

    # -- episode -----------------------------------------------------------------------

    @abstractmethod
    def layout(self, rng: np.random.Generator) -> Layout:
        """Seeded initial state of an episode; also resets the task's episode state."""

    def build_world(
        self, rng: np.random.Generator, config: SimConfig | None = None
    ) -> KinematicWorld:
        """A fresh world with this task spawned in it (roles and speed caps on the bodies)."""
        cfg = config or SimConfig(uavs=self.n_uavs, altitude_m=self.altitude_m)
        if cfg.uavs != self.n_uavs:
            raise ValueError(
                f"config flies {cfg.uavs} UAVs; this {self.name} task has {self.n_uavs}"
            )
        if cfg.altitude_m != self.altitude_m:
            raise ValueError(
                f"config altitude {cfg.altitude_m} m differs from the task's {self.altitude_m} m"
            )
        world = KinematicWorld.from_config(cfg)
        layout = self.layout(rng)
        for body in self.body_ids:
            role = self.role_of(body)
            world.add_uav(
                body,
                layout.positions[body],
                role=role,
                max_speed=self.spec.role(role).max_speed_mps,
            )
        for entity in layout.entities:
            world.add_entity(entity)
        return world

    # -- perception --------------------------------------------------------------------

    def sensing_radius(self, body: str) -> float:
        return self.spec.role(self.role_of(body)).sensing_radius_m

    def sensed(self, world: KinematicWorld, body: str) -> list[Entity]:
        """Entities and bodies (kind ``"uav"``) within the role's sensing radius. Tasks that
        hide things (forest occlusion) override this."""
        return world.sense(body, self.sensing_radius(body))

    def visible(self, world: KinematicWorld, body: str) -> list[Entity]:
        """What ``body`` perceives this round: what it senses, plus every static entity one
        of its private facts names (its goal landmark, its own formation slot) wherever that
        is: knowing *which* landmark is the goal includes knowing where it is, as mpe2's
        agents observe their goal. Nothing else crosses the sensing radius."""
        seen = self.sensed(world, body)
        ids = {e.id for e in seen}
        for value in self.private_facts(world, body).values():
            if value not in ids and world.has_entity(value):
                seen.append(world.entity(value))
                ids.add(value)
        return seen

    def facts(self, world: KinematicWorld, body: str) -> dict[str, str]:
        """This body's private facts (override). Only keys its role declares get through."""
        return {}

    def private_facts(self, world: KinematicWorld, body: str) -> dict[str, str]:
        """``facts`` filtered to what the body's role may know: another role's private fact
        can never reach it, whatever a subclass returns."""
        allowed = self.spec.role(self.role_of(body)).facts
        return {k: v for k, v in self.facts(world, body).items() if k in allowed}

    # -- talking -----------------------------------------------------------------------

    def reaches(
        self, sender: str, receiver: str, world: KinematicWorld, radius_m: float = COMM_RADIUS_M
    ) -> bool:
        """Whether a message ``sender`` sends now reaches ``receiver`` (routing + range)."""
        a, b = world.body(sender), world.body(receiver)
        distance = math.hypot(a.north - b.north, a.east - b.east)
        return self.spec.reaches(self.role_of(sender), self.role_of(receiver), distance, radius_m)

    # -- the world's own agents ----------------------------------------------------------

    def scripted_actions(
        self,
        world: KinematicWorld,
        round: int,
        inboxes: Mapping[str, Sequence[InboxMessage]],
    ) -> dict[str, Action]:
        """Fixed policies of the scripted bodies on the frozen state of 0-based ``round``;
        ``inboxes`` holds what listening bodies received last round."""
        return {}

    # -- commands ----------------------------------------------------------------------

    def record_guess(self, body: str, guess: str) -> bool:
        """A controlled UAV's guess (carried in its command). Returns whether it was valid
        and recorded; tasks without guesses ignore them."""
        return False

    # -- one round ---------------------------------------------------------------------

    def after_step(self, world: KinematicWorld) -> None:  # noqa: B027 - optional hook
        """Task dynamics after physics (pickups, deliveries, visits). Default: none."""

    @abstractmethod
    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        """Reward of every body (controlled and scripted) for the current state."""

    @abstractmethod
    def complete(self, world: KinematicWorld, round: int) -> bool:
        """The task's success flag for this state; ``round`` counts rounds played (1-based)."""

    def metrics(self, world: KinematicWorld) -> Metrics:
        """Extra per-round metrics; every task reports near collisions (pairs < 2 m)."""
        return {"near_collisions": float(world.near_collisions(NEAR_COLLISION_M))}


__all__ = [
    "HOLD_ACTION",
    "NE",
    "Action",
    "Layout",
    "Metrics",
    "ReferencePolicy",
    "TaskDefinition",
    "uav_id",
]
