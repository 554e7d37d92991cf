"""Termination rule and return accumulation of :class:`Episode`."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import ClassVar

import numpy as np
import pytest

from aeroweaver_edge.contracts.wire import InboxMessage, Vec3
from aeroweaver_edge.sim.episode import Episode
from aeroweaver_edge.tasks.base import Action, Layout, ReferencePolicy, TaskDefinition
from aeroweaver_edge.tasks.coverage import Coverage
from aeroweaver_edge.tasks.spec import RED, RoleSpec, TaskSpec
from aeroweaver_edge.world.kinematics import KinematicWorld

FLAGS = TaskSpec(
    name="flags",
    title="Flags",
    summary="a test task",
    description="",
    keywords=(),
    mission_text="",
    roles=(RoleSpec("pursuer", "", min_count=1),),
    role_counts=lambda n: {"pursuer": n},
    team_size=2,
    mpe_module="",
    scripted=(RoleSpec("evader", "", scripted=True, team=RED),),
    scripted_counts=lambda n: {"evader": 1},
)


class FlagTask(TaskDefinition):
    """A task whose completion flag per round is given up front; fixed rewards; the
    scripted evader flies north at 2 m/s and guesses "7" from round 1 on."""

    spec: ClassVar[TaskSpec] = FLAGS
    reference: ClassVar[ReferencePolicy]

    def __init__(self, flags: str, max_rounds: int | None = None) -> None:
        super().__init__(2, max_rounds=max_rounds)
        self.flags = [c == "T" for c in flags]
        self.calls = 0
        self.guesses: list[tuple[str, str]] = []
        self.heard: list[int] = []

    def layout(self, rng: np.random.Generator) -> Layout:
        return Layout({b: (10.0 * i, 0.0) for i, b in enumerate(self.body_ids)})

    def scripted_actions(
        self, world: KinematicWorld, round: int, inboxes: Mapping[str, Sequence[InboxMessage]]
    ) -> dict[str, Action]:
        self.heard.append(len(inboxes.get("evader0", ())))
        return {"evader0": Action((2.0, 0.0, 0.0), guess="7" if round >= 1 else None)}

    def record_guess(self, body: str, guess: str) -> bool:
        self.guesses.append((body, guess))
        return guess.isdigit()

    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        return {"uav0": -1.0, "uav1": -2.0, "evader0": 10.0}

    def complete(self, world: KinematicWorld, round: int) -> bool:
        flag = self.flags[self.calls] if self.calls < len(self.flags) else False
        self.calls += 1
        return flag


def run(task: FlagTask) -> Episode:
    episode = Episode(task, task.build_world(np.random.default_rng(0)))
    while not episode.done:
        episode.play_round({})
    return episode


def test_three_stable_rounds_complete() -> None:
    ep = run(FlagTask("TTT"))
    result = ep.result()
    assert (result.rounds, result.reason, result.stable_rounds) == (3, "complete", 3)
    assert result.returns == {"uav0": -3.0, "uav1": -6.0, "evader0": 30.0}
    assert result.team_mean_return == pytest.approx(-4.5)  # evader is scripted: excluded


def test_a_broken_streak_resets() -> None:
    ep = run(FlagTask("TTFTTFFTTT"))
    assert (ep.round, ep.reason) == (10, "complete")


def test_horizon_ends_the_episode() -> None:
    ep = run(FlagTask(""))
    assert (ep.round, ep.reason, ep.stable_rounds) == (24, "horizon", 0)
    assert ep.result().returns["uav0"] == -24.0
    short = run(FlagTask("FFFTT", max_rounds=5))
    assert (short.round, short.reason, short.stable_rounds) == (5, "horizon", 2)


def test_completion_wins_on_the_last_round() -> None:
    ep = run(FlagTask("FFTTT", max_rounds=5))
    assert (ep.round, ep.reason) == (5, "complete")


def test_no_round_after_the_end_and_no_result_before() -> None:
    ep = Episode(FlagTask("TTT"), FlagTask("").build_world(np.random.default_rng(0)))
    with pytest.raises(RuntimeError, match="still running"):
        ep.result()
    for _ in range(3):
        ep.advance()
    with pytest.raises(RuntimeError, match="already ended"):
        ep.advance()


def test_commands_hold_or_persist() -> None:
    task = FlagTask("")
    ep = Episode(task, task.build_world(np.random.default_rng(0)))
    ep.play_round({"uav0": (5.0, 0.0, 0.0), "uav1": (0.0, 5.0, 0.0)})
    ep.play_round({"uav1": None})
    world = ep.world
    assert world.body("uav0").vel == pytest.approx((5.0, 0.0, 0.0))  # kept
    assert world.body("uav1").vel == (0.0, 0.0, 0.0)  # held
    assert world.body("evader0").vel == pytest.approx((2.0, 0.0, 0.0))  # the world flies it


def test_guesses_go_to_the_task_and_are_logged() -> None:
    task = FlagTask("")
    ep = Episode(task, task.build_world(np.random.default_rng(0)))
    ep.play_round({}, guesses={"uav1": "3"})
    ep.play_round({}, guesses={"uav1": "x"})
    assert task.guesses == [("uav1", "3"), ("evader0", "7"), ("uav1", "x")]
    assert ep.guesses["uav1"] == [(0, "3", True), (1, "x", False)]
    assert ep.guesses["evader0"] == [(1, "7", True)]


def test_scripted_agents_get_their_inbox() -> None:
    task = FlagTask("")
    ep = Episode(task, task.build_world(np.random.default_rng(0)))
    ep.play_round({})
    assert task.heard == [0]


def test_team_mean_is_nan_when_nobody_is_controlled() -> None:
    task = FlagTask("")
    ep = Episode(task, task.build_world(np.random.default_rng(0)), max_rounds=1)
    ep.advance()
    ep.returns = {"evader0": 1.0}
    assert math.isnan(ep.team_mean_return())


def test_coverage_episode_flown_onto_the_landmarks_completes() -> None:
    """A greedy proportional controller: each UAV flies to its landmark and stops on it."""
    task = Coverage(3)
    world = task.build_world(np.random.default_rng(66001))
    ep = Episode(task, world)
    while not ep.done:
        commands: dict[str, Vec3 | None] = {}
        for i, uav in enumerate(world.uav_ids):
            body, target = world.body(uav), world.entity(f"L{i}").pos
            dn, de = target[0] - body.north, target[1] - body.east
            commands[uav] = (dn, de, 0.0)  # speed = distance: stops on the target
        ep.play_round(commands)
    result = ep.result()
    assert result.reason == "complete"
    assert result.rounds < 24
    assert result.metrics["covered_landmarks"] == 3.0
    # Returns are the sums of the per-round rewards (undiscounted, all negative here).
    assert all(r < 0 for r in result.returns.values())
    assert result.team_mean_return == pytest.approx(sum(result.returns.values()) / 3)
