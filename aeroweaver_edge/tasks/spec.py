"""What a task *is*, as data: roles, counts, goals, routing, wording (the Commander's view).

A ``TaskSpec`` is everything about a task that needs no simulator: the Commander validates a
task record against it, the rule parser and its BM25 fallback read its wording, role
assignment reads its roles and goals, the daemon's peer channel reads its message routing,
and the simulator reads its sensing radii and scripted roles. Each task module defines
exactly one (``SPEC``) next to its simulation code (``aeroweaver_edge.tasks.<name>``).

Nothing here imports numpy, mpe2 or the simulator, so a daemon or the Commander can read a
spec cheaply.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from aeroweaver_edge.contracts.defaults import COMM_RADIUS_M, MAX_ROUNDS, MAX_UAVS, SENSING_RADIUS_M

BLUE = "blue"
"""The controlled team (our UAVs)."""
RED = "red"
"""Opponents flown by the world."""

Cue = tuple[str, int]
"""A rule-parser cue: a regular expression over the lower-cased mission text and its weight
(2: names the task on its own, 1: a supporting word)."""


@dataclass(frozen=True)
class RoleSpec:
    """One role of a task, with bounds on how many bodies take it."""

    name: str
    goal: str
    """Template local goal the Commander hands to a UAV of this role."""
    min_count: int = 0
    max_count: int | None = None  # None: unbounded (up to the swarm cap)
    stationary: bool = False
    """Stationary roles get only skills that name their role, plus hold."""
    scripted: bool = False
    """Flown by the world's fixed policy, not by a daemon; not evaluated."""
    team: str = BLUE
    sensing_radius_m: float = SENSING_RADIUS_M
    facts: tuple[str, ...] = ()
    """Names of the private facts (``Observation.facts``) a body of this role receives."""
    nouns: str = ""
    """Regular expression of nouns operators use for this role ("chasers?|hunters?")."""
    max_speed_mps: float | None = None  # None: the world's cap
    listens: bool = False
    """A scripted role that receives peer messages (the eavesdropper): the world gives it an
    inbox on the mesh."""

    def allows(self, n: int) -> bool:
        return n >= self.min_count and (self.max_count is None or n <= self.max_count)

    def bounds_text(self) -> str:
        return f"{self.min_count}..{'n' if self.max_count is None else self.max_count}"


def _no_scripted(n: int) -> dict[str, int]:
    return {}


@dataclass(frozen=True)
class TaskSpec:
    """The nine benchmark tasks each define one of these (``SPEC`` in the task module)."""

    name: str
    title: str
    summary: str
    """One line: what the task is (shown to the LLM among the task types)."""
    description: str
    """A paragraph in plain words; the rule parser's BM25 fallback indexes it."""
    keywords: tuple[str, ...]
    mission_text: str
    """The template mission: what ``aeroweaver sim <task>`` tells the swarm."""
    roles: tuple[RoleSpec, ...]
    """Roles our UAVs play (daemons), in template order."""
    role_counts: Callable[[int], dict[str, int]]
    """Template counts of our roles for n controlled UAVs (the note's default roles)."""
    team_size: int
    """Controlled UAVs when the mission states no number."""
    mpe_module: str
    """The mpe2 scenario whose reward functions score the task."""
    scripted: tuple[RoleSpec, ...] = ()
    scripted_counts: Callable[[int], dict[str, int]] = _no_scripted
    """Bodies the world flies for n controlled UAVs, by role."""
    cues: tuple[Cue, ...] = ()
    routes: tuple[tuple[str, str], ...] = ()
    """(sender role, receiver role) pairs that reach each other regardless of range."""
    stable_rounds: int = 3
    """Consecutive complete rounds that end an episode as complete."""
    max_rounds: int = MAX_ROUNDS
    notes: tuple[str, ...] = field(default_factory=tuple)

    # -- roles -------------------------------------------------------------------------

    @property
    def role_names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.roles)

    @property
    def scripted_names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.scripted)

    @property
    def all_roles(self) -> tuple[RoleSpec, ...]:
        return (*self.roles, *self.scripted)

    def role(self, name: str) -> RoleSpec:
        for r in self.all_roles:
            if r.name == name:
                return r
        raise KeyError(f"{name!r} is not a role of {self.name}")

    def has_role(self, name: str) -> bool:
        return any(r.name == name for r in self.all_roles)

    # -- sizes -------------------------------------------------------------------------

    @property
    def min_uavs(self) -> int:
        """Fewest controlled UAVs the roles' lower bounds allow (at least one)."""
        return max(1, sum(r.min_count for r in self.roles))

    @property
    def max_uavs(self) -> int:
        """Most controlled UAVs: the roles' upper bounds, capped at the swarm limit."""
        if any(r.max_count is None for r in self.roles):
            return MAX_UAVS
        return min(MAX_UAVS, sum(r.max_count or 0 for r in self.roles))

    def size_ok(self, n: int) -> bool:
        return self.min_uavs <= n <= self.max_uavs

    def describe_size(self) -> str:
        lo, hi = self.min_uavs, self.max_uavs
        roles = ", ".join(self.role_names)
        if lo == hi:
            return f"exactly {lo} UAVs ({roles})"
        return f"{lo} to {hi} UAVs ({roles})"

    def check_counts(self, counts: Mapping[str, int]) -> str | None:
        """Why these counts of our roles do not fit the task, or None if they do."""
        unknown = [r for r in counts if r not in self.role_names]
        if unknown:
            return f"{', '.join(map(repr, unknown))} not a role of {self.name}"
        for r in self.roles:
            n = counts.get(r.name, 0)
            if not r.allows(n):
                return f"{r.name}: {n} is outside {r.bounds_text()} for {self.name}"
        total = sum(counts.values())
        if not self.size_ok(total):
            return f"{self.name} needs {self.describe_size()}, got {total}"
        return None

    # -- talking -----------------------------------------------------------------------

    def reaches(
        self,
        sender_role: str,
        receiver_role: str,
        distance_m: float,
        radius_m: float = COMM_RADIUS_M,
    ) -> bool:
        """Whether a message from ``sender_role`` reaches ``receiver_role`` at this distance:
        routed pairs always; otherwise the same team within the communication radius."""
        if (sender_role, receiver_role) in self.routes:
            return True
        return self.team_of(sender_role) == self.team_of(receiver_role) and distance_m <= radius_m

    def team_of(self, role: str) -> str:
        for r in self.all_roles:
            if r.name == role:
                return r.team
        return BLUE  # an unknown role (e.g. "unassigned") is on our side

    def sensing_radius(self, role: str) -> float:
        for r in self.all_roles:
            if r.name == role:
                return r.sensing_radius_m
        return SENSING_RADIUS_M

    def corpus_text(self) -> str:
        """What the rule parser's BM25 fallback indexes for this task."""
        roles = " ".join(f"{r.name} {r.nouns.replace('|', ' ')} {r.goal}" for r in self.all_roles)
        return "\n".join(
            [self.title, self.summary, self.description, " ".join(self.keywords), roles]
        )


__all__ = ["BLUE", "RED", "Cue", "RoleSpec", "TaskSpec"]
