"""The ports the daemon's core talks to. Backends (sim, MAVLink, MAVSDK, LLM servers, a
Zenoh or in-memory peer channel) implement these; the core never imports a backend.

Everything here sits at the bottom of the package: it imports only plain types
(``observation``, ``scores``, ``wire``), never the agent, LLM or simulator layers.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

from aeroweaver_edge.contracts.observation import Observation, VehicleState
from aeroweaver_edge.contracts.scores import LabelScores
from aeroweaver_edge.contracts.wire import Entity, InboxMessage, MessagePurpose, MsgRef, Vec3

Scalar = str | int | float | bool


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
    experience_from: tuple[str, ...] = ()  # lockstep: peers whose last-round record comes


class Clock(Protocol):
    async def next_round(self) -> RoundTick | None:
        """Wait for the next round; ``None`` when the run is over."""
        ...

    async def finish(
        self, tick: RoundTick, *, sent: Sequence[MsgRef], guess: str | None = None
    ) -> None:
        """Close the round. A wall clock does nothing; a lockstep simulator learns that
        this UAV is done, which messages it sent (so recipients can wait for them) and the
        guess its skill recorded, if any (the world scores guesses)."""
        ...


@dataclass(frozen=True)
class Percept:
    """What the Perception port delivers for one round, frozen at the tick: own state, the
    entities within this UAV's sensing radius, and its private facts (role-restricted)."""

    own: VehicleState
    entities: Sequence[Entity] = ()
    facts: Mapping[str, str] = field(default_factory=dict)


class Perception(Protocol):
    async def sense(self, tick: RoundTick) -> Percept:
        """Own state, entities in range and private facts, frozen at the tick."""
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
    task: str = ""  # the mission's task type (what a task's reference policy is looked up by)
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


Reach = Callable[[str, str, float], bool]
"""Message routing: ``reach(sender_role, receiver_role, distance_m)``."""


class PeerChannel(Protocol):
    """The talk side of a daemon (DESIGN §4 steps 2 and 6): its beacon, its inbox, its sends,
    the live roster. ``aeroweaver_edge.mesh.peers.PeerLink`` serves it over Zenoh;
    ``aeroweaver_edge.mesh.peer_memory.MemoryPeerHub`` serves it in memory (tests, benchmarks).

    Semantics both implementations keep:

    * ``send(to="*")`` broadcasts; any other ``to`` is one directed message. Sending never
      waits for peers. Whether a message *reaches* a peer is judged at the receiver on the
      positions of the round it was sent (the sender's position rides in the message, the
      receiver's own comes from its beacon of that round) with the routing rule set by
      ``set_routing``; messages that do not reach are dropped there and counted.
    * ``collect_inbox`` waits (bounded) for the expected messages, then returns every
      accepted message of rounds up to ``max_round``, sorted by (sender, sequence); later
      rounds stay queued.
    """

    @property
    def roster(self) -> frozenset[str]:
        """Live peers, not including this UAV."""
        ...

    def set_routing(self, role: str, reach: Reach) -> None:
        """This UAV's role and the routing rule of its current mission."""
        ...

    def publish_beacon(
        self, round: int, pos: Vec3, vel: Vec3, role: str = "", status: str = "nominal"
    ) -> None: ...

    async def collect_inbox(
        self,
        expect: Iterable[MsgRef] = (),
        timeout_s: float = 1.0,
        *,
        max_round: int | None = None,
    ) -> list[InboxMessage]: ...

    async def send(
        self,
        to: str,
        kind: str,
        body: Mapping[str, Scalar],
        *,
        round: int,
        purpose: MessagePurpose = "coordination",
    ) -> MsgRef | None:
        """``None`` when the message could not be sent at all (closed, unknown peer)."""
        ...


@dataclass
class DaemonPorts:
    """Every port one daemon talks to, as its backends (``daemon.app``) provide them."""

    vehicle: Vehicle
    clock: Clock
    perception: Perception
    rewards: RewardSource
    peers: PeerChannel | None = None  # None: a Zenoh PeerLink on the daemon's own mesh
