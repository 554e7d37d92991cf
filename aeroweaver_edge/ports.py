"""The ports the daemon's core talks to. Backends (sim, MAVLink, MAVSDK, LLM servers)
implement these; the core never imports a backend."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from aeroweaver_edge.agent.scoring import LabelScores
from aeroweaver_edge.observation import Observation, VehicleState
from aeroweaver_edge.wire import Entity, MsgRef


@dataclass(frozen=True)
class Health:
    ok: bool
    detail: str = ""


class Vehicle(Protocol):
    """The UAV's own body. Commands act on this vehicle only."""

    async def state(self) -> VehicleState: ...
    async def arm(self) -> None: ...
    async def takeoff(self, altitude_m: float) -> None: ...
    async def set_velocity(self, north: float, east: float, down: float) -> None: ...
    async def goto(self, north: float, east: float, down: float) -> None: ...
    async def hold(self) -> None: ...
    async def land(self) -> None: ...
    async def return_home(self) -> None: ...
    async def health(self) -> Health: ...


@dataclass(frozen=True)
class RoundTick:
    """The trigger for one decision round."""

    episode: int
    round: int
    deadline_s: float  # seconds this round may take before the UAV is treated as holding
    expect: tuple[MsgRef, ...] = ()  # lockstep: peer messages known to be on their way


class Clock(Protocol):
    async def next_round(self) -> RoundTick | None:
        """Wait for the next round; ``None`` when the run is over."""
        ...

    async def finish(self, tick: RoundTick, sent: Sequence[MsgRef]) -> None:
        """Close the round. A wall clock does nothing; a lockstep simulator learns that
        this UAV is done and which messages it sent, so recipients can wait for them."""
        ...


class Perception(Protocol):
    async def sense(self, tick: RoundTick) -> tuple[VehicleState, Sequence[Entity]]:
        """Own state and the entities within sensing range, frozen at the tick."""
        ...


@dataclass(frozen=True)
class RewardEvent:
    episode: int
    round: int
    reward: float
    done: bool
    source: str


class RewardSource(Protocol):
    def drain(self) -> list[RewardEvent]:
        """Rewards that arrived since the last call (simulator or a field scorer)."""
        ...


@dataclass(frozen=True)
class Candidate:
    """One callable (skill, parameters) pair with its single-token label."""

    label: str
    skill: str
    params: dict[str, str | int | float]
    text: str  # e.g. ``cover_landmark(target_id=L2)``


@dataclass(frozen=True)
class DecisionRequest:
    observation: Observation
    mission_text: str
    role: str
    local_goal: str
    constraints: Sequence[str]
    skill_docs: Sequence[str]
    observation_text: str
    candidates: Sequence[Candidate]
    history: Sequence[str] | None = None
    """The agent's own recent rounds (``agent.history``), oldest first; None: no history."""


class Selector(Protocol):
    """Scores labelled candidates. The LLM selector and the scripted scorer share this."""

    name: str

    @property
    def label_budget(self) -> int | None:
        """How many labels (A, B, ...) this selector can score; ``None``: no limit known."""
        ...

    async def score(self, request: DecisionRequest) -> LabelScores: ...

    async def aclose(self) -> None: ...
