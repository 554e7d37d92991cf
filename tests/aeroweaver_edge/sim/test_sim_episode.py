"""Termination rule and return accumulation of :class:`Episode`."""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import pytest

from aeroweaver_edge.sim.episode import Episode
from aeroweaver_edge.sim.tasks.base import Task
from aeroweaver_edge.sim.tasks.coverage import CoverageTask
from aeroweaver_edge.sim.world import KinematicWorld
from aeroweaver_edge.wire import Entity, Vec3


class FlagTask(Task):
    """A task whose completion flag per round is given up front; fixed rewards."""

    name: ClassVar[str] = "flags"
    scripted_roles: ClassVar[frozenset[str]] = frozenset({"evader"})

    def __init__(self, flags: str, max_rounds: int | None = None) -> None:
        super().__init__(3, max_rounds=max_rounds)
        self.flags = [c == "T" for c in flags]
        self.calls = 0

    def spawn(self, rng: np.random.Generator, n_uavs: int) -> tuple[list[Vec3], list[Entity]]:
        return [(10.0 * i, 0.0, -5.0) for i in range(n_uavs)], []

    def roles(self) -> dict[str, str]:
        return {"uav0": "pursuer", "uav1": "pursuer", "uav2": "evader"}

    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        return {"uav0": -1.0, "uav1": -2.0, "uav2": 10.0}

    def complete(self, world: KinematicWorld) -> bool:
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
    assert result.returns == {"uav0": -3.0, "uav1": -6.0, "uav2": 30.0}
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
    assert world.body("uav2").vel == (0.0, 0.0, 0.0)


def test_team_mean_is_nan_when_everyone_is_scripted() -> None:
    task = FlagTask("")
    task.roles = lambda: dict.fromkeys(task.uav_ids, "evader")  # type: ignore[method-assign]
    ep = Episode(task, task.build_world(np.random.default_rng(0)), max_rounds=1)
    ep.advance()
    assert math.isnan(ep.result().team_mean_return)


def test_coverage_episode_flown_onto_the_landmarks_completes() -> None:
    """A greedy proportional controller: each UAV flies to its landmark and stops on it."""
    task = CoverageTask(3)
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
