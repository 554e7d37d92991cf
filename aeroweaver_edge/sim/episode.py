"""The authors' episode loop and termination rule, independent of how decisions are made.

Each round (notes/mpe-tasks.md): decisions are applied to the world, the world advances one
round, rewards are evaluated on the new state and added *undiscounted* to each UAV's return,
then the task's completion flag is checked once. ``stable_rounds`` counts consecutive
complete rounds (an incomplete round resets it); the episode ends as ``"complete"`` at
``stable_rounds >= task.stable_rounds_needed``, else as ``"horizon"`` at
``round >= max_rounds``. Completion wins when both happen in the same round.

Keeping this apart from the networked runner lets the benchmark, scripted baselines and
tests share one definition of "return" and "done".
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

from aeroweaver_edge.sim.tasks.base import Metrics, Task
from aeroweaver_edge.sim.world import KinematicWorld
from aeroweaver_edge.wire import Vec3

EndReason = Literal["complete", "horizon"]


@dataclass(frozen=True, slots=True)
class RoundResult:
    round: int  # 1-based: the number of rounds played so far
    rewards: dict[str, float]
    complete: bool
    stable_rounds: int
    metrics: Metrics
    done: bool
    reason: EndReason | None


@dataclass(frozen=True, slots=True)
class EpisodeResult:
    task: str
    rounds: int
    reason: EndReason
    returns: dict[str, float]
    team_mean_return: float  # over UAVs whose role is not scripted (NaN if there are none)
    stable_rounds: int
    metrics: Metrics = field(default_factory=dict)  # of the final round


class Episode:
    """Runs the termination rule and accumulates returns for one task in one world."""

    def __init__(self, task: Task, world: KinematicWorld, max_rounds: int | None = None) -> None:
        self.task = task
        self.world = world
        self.max_rounds = task.max_rounds if max_rounds is None else max_rounds
        if self.max_rounds < 1:
            raise ValueError(f"max_rounds must be >= 1, got {self.max_rounds}")
        self.round = 0
        self.stable_rounds = 0
        self.returns = {u: 0.0 for u in world.uav_ids}
        self.reason: EndReason | None = None
        self.last_metrics: Metrics = {}

    @property
    def done(self) -> bool:
        return self.reason is not None

    def apply(self, commands: Mapping[str, Vec3 | None]) -> None:
        """Apply this round's decisions: a velocity, or ``None`` for an own-body hold.

        UAVs missing from ``commands`` keep their previous setpoint (commands persist).
        """
        for uav, vel in commands.items():
            if vel is None:
                self.world.hold(uav)
            else:
                self.world.set_velocity(uav, vel)

    def advance(self) -> RoundResult:
        """Step the world one round, then score it and apply the termination rule."""
        if self.done:
            raise RuntimeError(f"episode already ended ({self.reason}) after {self.round} rounds")
        self.world.step()
        self.round += 1
        rewards = self.task.rewards(self.world)
        for uav, r in rewards.items():
            self.returns[uav] = self.returns.get(uav, 0.0) + r
        complete = self.task.complete(self.world)
        self.stable_rounds = self.stable_rounds + 1 if complete else 0
        if self.stable_rounds >= self.task.stable_rounds_needed:
            self.reason = "complete"
        elif self.round >= self.max_rounds:
            self.reason = "horizon"
        self.last_metrics = self.task.metrics(self.world)
        return RoundResult(
            round=self.round,
            rewards=rewards,
            complete=complete,
            stable_rounds=self.stable_rounds,
            metrics=self.last_metrics,
            done=self.done,
            reason=self.reason,
        )

    def play_round(self, commands: Mapping[str, Vec3 | None]) -> RoundResult:
        self.apply(commands)
        return self.advance()

    def team_mean_return(self) -> float:
        roles, scripted = self.task.roles(), self.task.scripted_roles
        controlled = [r for u, r in self.returns.items() if roles.get(u) not in scripted]
        return math.fsum(controlled) / len(controlled) if controlled else math.nan

    def result(self) -> EpisodeResult:
        if self.reason is None:
            raise RuntimeError(f"episode still running after {self.round} rounds")
        return EpisodeResult(
            task=self.task.name,
            rounds=self.round,
            reason=self.reason,
            returns=dict(self.returns),
            team_mean_return=self.team_mean_return(),
            stable_rounds=self.stable_rounds,
            metrics=dict(self.last_metrics),
        )
