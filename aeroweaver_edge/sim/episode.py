"""The authors' episode loop and termination rule, independent of how decisions are made.

Each round (docs/notes/mpe-tasks.md): the world's own agents decide on the frozen state, every
decision is applied (a velocity, or a hold; a guess is recorded by the task), the world
advances one round, the task's dynamics run (pickups, deliveries, visits), rewards are
evaluated on the new state and added *undiscounted* to each body's return, then the task's
completion flag is checked once. ``stable_rounds`` counts consecutive complete rounds (an
incomplete round resets it); the episode ends as ``"complete"`` at ``stable_rounds >=
task.stable_rounds_needed``, else as ``"horizon"`` at ``round >= max_rounds``. Completion wins
when both happen in the same round.

Keeping this apart from the networked runner lets the benchmark, scripted baselines and
tests share one definition of "return" and "done". The reported return is the mean over
the controlled (not scripted) bodies, as in the paper.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

from aeroweaver_edge.contracts.wire import InboxMessage, Vec3
from aeroweaver_edge.tasks.base import Action, Metrics, TaskDefinition
from aeroweaver_edge.world.kinematics import KinematicWorld

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
    returns: dict[str, float]  # every body, scripted ones included
    team_mean_return: float  # over the controlled bodies (NaN if there are none)
    stable_rounds: int
    metrics: Metrics = field(default_factory=dict)  # of the final round


class Episode:
    """Runs the termination rule and accumulates returns for one task in one world."""

    def __init__(
        self, task: TaskDefinition, world: KinematicWorld, max_rounds: int | None = None
    ) -> None:
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
        self.guesses: dict[str, list[tuple[int, str, bool]]] = {}  # body -> (round, guess, ok)

    @property
    def done(self) -> bool:
        return self.reason is not None

    def scripted(
        self, inboxes: Mapping[str, Sequence[InboxMessage]] | None = None
    ) -> dict[str, Action]:
        """The world-flown bodies' actions for this round, on the frozen state."""
        return self.task.scripted_actions(self.world, self.round, inboxes or {})

    def apply(
        self,
        commands: Mapping[str, Vec3 | None],
        guesses: Mapping[str, str] | None = None,
    ) -> None:
        """Apply this round's decisions: a velocity, or ``None`` for an own-body hold, and
        the guesses that came with them (recorded and scored by the task).

        Bodies missing from ``commands`` keep their previous setpoint (commands persist).
        """
        for uav, vel in commands.items():
            if vel is None:
                self.world.hold(uav)
            else:
                self.world.set_velocity(uav, vel)
        for uav, guess in (guesses or {}).items():
            ok = self.task.record_guess(uav, guess)
            self.guesses.setdefault(uav, []).append((self.round, guess, ok))

    def apply_actions(self, actions: Mapping[str, Action]) -> None:
        self.apply(
            {b: a.vel for b, a in actions.items()},
            {b: a.guess for b, a in actions.items() if a.guess is not None},
        )

    def advance(self) -> RoundResult:
        """Step the world one round, then score it and apply the termination rule."""
        if self.done:
            raise RuntimeError(f"episode already ended ({self.reason}) after {self.round} rounds")
        self.world.step()
        self.task.after_step(self.world)
        self.round += 1
        rewards = self.task.rewards(self.world)
        for uav, r in rewards.items():
            self.returns[uav] = self.returns.get(uav, 0.0) + r
        complete = self.task.complete(self.world, self.round)
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

    def play_round(
        self,
        commands: Mapping[str, Vec3 | None],
        guesses: Mapping[str, str] | None = None,
        inboxes: Mapping[str, Sequence[InboxMessage]] | None = None,
    ) -> RoundResult:
        """One whole round: the world's agents, then ``commands`` for the controlled ones."""
        self.apply_actions(self.scripted(inboxes))
        self.apply(commands, guesses)
        return self.advance()

    def team_mean_return(self) -> float:
        controlled = [r for u, r in self.returns.items() if not self.task.is_scripted(u)]
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
