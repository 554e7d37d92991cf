"""What a skill executor may ask for: typed intents, applied only to the UAV's own body.

Executors never touch a vehicle. They return an ``Intent`` that the daemon passes through
the safety gate and then to its own Vehicle port.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from aeroweaver_edge.contracts.wire import MessagePurpose, Vec3


@dataclass(frozen=True)
class Hold:
    """Zero velocity; clears any motion target."""


@dataclass(frozen=True)
class MoveTo:
    """Fly toward a point (NED metres) at up to ``speed`` m/s (None: the envelope's cap)."""

    target: Vec3
    speed: float | None = None


@dataclass(frozen=True)
class SetVelocity:
    vel: Vec3


Motion = Hold | MoveTo | SetVelocity


@dataclass(frozen=True)
class VehicleAction:
    """A change of the vehicle's flight state (not a motion): take off, land, return home.

    The daemon's flight phases carry it out through the Vehicle port after an approval
    check; the motion that goes with it is always Hold.
    """

    kind: Literal["takeoff", "land", "return_home"]
    altitude_m: float | None = None  # take-off height; None: the mission flight level


@dataclass(frozen=True)
class Outgoing:
    """A directed message to a named peer (or ``"*"`` for every reachable peer).

    ``purpose``: ``"task"`` for what the task cannot be done without (the speaker's goal,
    the sender's ciphertext), ``"coordination"`` for reports that only help peers coordinate
    (intent, target, status); the "without coordination reports" ablation drops the latter.
    """

    to: str
    kind: str
    body: dict[str, str | int | float | bool] = field(default_factory=dict)
    purpose: MessagePurpose = "coordination"


@dataclass(frozen=True)
class Intent:
    motion: Motion
    messages: tuple[Outgoing, ...] = ()
    memo: dict[str, str] = field(default_factory=dict)  # facts the skill wants kept (e.g. a guess)
    action: VehicleAction | None = None  # flight: a vehicle action for the daemon's phases


HOLD = Intent(Hold())
