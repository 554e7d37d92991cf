"""Every task's termination rule at its boundary, in worlds built body by body.

Distances are exact: targets sit at whole metres and bodies exactly 3.0 (or 6.0) m away
along one axis, so "within 3 m" is tested at 3.0 (complete) and at 3.0 + 1e-9 (not). The
stable-rounds rule is played through :class:`Episode` with the bodies at rest: a task that
needs 3 consecutive complete rounds is still running after 2 and complete after 3; pursuit,
collection and private communication end on the first complete round.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pytest

from aeroweaver_edge.contracts.wire import Entity
from aeroweaver_edge.sim.episode import Episode
from aeroweaver_edge.tasks import create
from aeroweaver_edge.tasks.base import TaskDefinition
from aeroweaver_edge.tasks.collection_delivery import CollectionDelivery
from aeroweaver_edge.tasks.formation import Formation
from aeroweaver_edge.tasks.guided_navigation import GuidedNavigation
from aeroweaver_edge.tasks.pursuit_evasion import PursuitEvasion
from aeroweaver_edge.world.kinematics import KinematicWorld

JUST_OUT = 3.0 + 1e-9
NE = tuple[float, float]


def world_of(
    task: TaskDefinition, at: Mapping[str, NE], entities: list[Entity] | None = None
) -> KinematicWorld:
    """A world with every body of ``task`` at rest where ``at`` puts it (default: parked far
    apart on the south edge) and ``entities`` (default: the task's own seeded layout)."""
    layout = task.layout(np.random.default_rng(7))  # also sets the episode's private state
    world = KinematicWorld()
    for k, body in enumerate(task.body_ids):
        world.add_uav(body, at.get(body, (-65.0, -60.0 + 12.0 * k)), role=task.role_of(body))
    for e in layout.entities if entities is None else entities:
        world.add_entity(e)
    return world


def landmark(lid: str, n: float, e: float) -> Entity:
    return Entity(id=lid, kind="landmark", pos=(n, e, -5.0))


def assert_needs_three_stable_rounds(task: TaskDefinition, world: KinematicWorld) -> None:
    ep = Episode(task, world)
    seen = [(r.complete, r.stable_rounds, r.done) for r in (ep.advance() for _ in range(3))]
    assert seen == [(True, 1, False), (True, 2, False), (True, 3, True)]
    assert ep.result().reason == "complete"
    assert ep.result().rounds == 3


def assert_ends_on_first_complete_round(task: TaskDefinition, world: KinematicWorld) -> None:
    ep = Episode(task, world)
    r = ep.advance()
    assert (r.complete, r.stable_rounds, r.done, r.reason) == (True, 1, True, "complete")


def assert_never_completes(task: TaskDefinition, world: KinematicWorld) -> None:
    ep = Episode(task, world, 4)
    results = [ep.advance() for _ in range(4)]
    assert [r.complete for r in results] == [False] * 4
    assert ep.reason == "horizon"


# ------------------------------------------------------------------ coverage

LANDMARKS = [landmark("L0", -30.0, 20.0), landmark("L1", 0.0, 30.0), landmark("L2", 30.0, 20.0)]


@pytest.mark.parametrize("axis", [0, 1])
def test_coverage_counts_a_landmark_at_exactly_3_m(axis: int) -> None:
    task = create("coverage", 3)
    step = (3.0, 0.0) if axis == 0 else (0.0, -3.0)
    at = {
        u: (lm.pos[0] + step[0], lm.pos[1] + step[1])
        for u, lm in zip(task.uav_ids, LANDMARKS, strict=True)
    }
    world = world_of(task, at, LANDMARKS)
    assert task.complete(world, 1)
    assert task.metrics(world)["covered_landmarks"] == 3.0
    assert_needs_three_stable_rounds(task, world)


def test_coverage_is_incomplete_a_nanometre_beyond_3_m() -> None:
    task = create("coverage", 3)
    at = {u: (lm.pos[0] + 3.0, lm.pos[1]) for u, lm in zip(task.uav_ids, LANDMARKS, strict=True)}
    at["uav2"] = (LANDMARKS[2].pos[0] + JUST_OUT, LANDMARKS[2].pos[1])
    world = world_of(task, at, LANDMARKS)
    assert not task.complete(world, 1)
    assert task.metrics(world)["covered_landmarks"] == 2.0
    assert_never_completes(task, world)


def test_coverage_needs_every_landmark_not_every_uav() -> None:
    task = create("coverage", 3)
    # Two UAVs on L0 and L1; the third parked far away leaves L2 uncovered.
    at = {"uav0": (-30.0, 20.0), "uav1": (0.0, 30.0)}
    assert not task.complete(world_of(task, at, LANDMARKS), 1)


def test_a_broken_streak_starts_over() -> None:
    """Complete, complete, one body nudged out for a round, back: 3 more rounds needed."""
    task = create("coverage", 3)
    at = {u: (lm.pos[0], lm.pos[1]) for u, lm in zip(task.uav_ids, LANDMARKS, strict=True)}
    world = world_of(task, at, LANDMARKS)
    ep = Episode(task, world)
    body = world.body("uav1")
    trace = []
    for rnd in range(6):
        body.north = 0.0 + (JUST_OUT if rnd == 2 else 0.0)  # out during round 3 only
        trace.append((ep.advance().stable_rounds, ep.done))
    assert trace == [(1, False), (2, False), (0, False), (1, False), (2, False), (3, True)]


# ------------------------------------------------------------------ guided navigation


def navigation(n_listeners: int, off: list[float]) -> tuple[GuidedNavigation, KinematicWorld]:
    task = create("guided_navigation", n_listeners + 1)
    assert isinstance(task, GuidedNavigation)
    world = world_of(task, {}, LANDMARKS)
    goal = world.entity(task.goal).pos
    for k, lid in enumerate(task.listeners):
        world.body(lid).north, world.body(lid).east = goal[0], goal[1] + off[k]
    return task, world


def test_navigation_completes_with_every_listener_at_exactly_3_m() -> None:
    task, world = navigation(2, [3.0, -3.0])
    assert task.complete(world, 1)
    assert_needs_three_stable_rounds(task, world)


def test_navigation_is_incomplete_if_one_listener_is_just_outside() -> None:
    task, world = navigation(2, [3.0, JUST_OUT])
    assert not task.complete(world, 1)
    assert_never_completes(task, world)


# ------------------------------------------------------------------ formations


@pytest.mark.parametrize("name", ["circular_formation", "line_formation"])
def test_formation_completes_with_every_member_at_exactly_3_m_from_its_slot(name: str) -> None:
    task = create(name, 4)
    assert isinstance(task, Formation)
    world = world_of(task, {})
    task.slots = [(10.0 * k, 18.0) for k in range(4)]  # whole metres: exact distances
    for k, m in enumerate(task.members):
        world.body(m).north, world.body(m).east = 10.0 * k, 18.0 + (3.0 if k % 2 else -3.0)
    assert task.complete(world, 1)
    assert task.metrics(world)["members_in_slot"] == 4.0
    assert_needs_three_stable_rounds(task, world)


@pytest.mark.parametrize("name", ["circular_formation", "line_formation"])
def test_formation_is_incomplete_with_one_member_just_outside(name: str) -> None:
    task = create(name, 4)
    assert isinstance(task, Formation)
    world = world_of(task, {})
    task.slots = [(10.0 * k, 18.0) for k in range(4)]
    for k, m in enumerate(task.members):
        world.body(m).north, world.body(m).east = 10.0 * k + (JUST_OUT if k == 3 else 3.0), 18.0
    assert not task.complete(world, 1)
    assert task.metrics(world)["members_in_slot"] == 3.0
    assert_never_completes(task, world)


def test_a_member_in_another_members_slot_does_not_count() -> None:
    task = create("line_formation", 2)
    assert isinstance(task, Formation)
    world = world_of(task, {})
    task.slots = [(0.0, 18.0), (20.0, 18.0)]
    world.body("uav0").north, world.body("uav0").east = 20.0, 18.0  # uav1's slot
    world.body("uav1").north, world.body("uav1").east = 0.0, 18.0  # uav0's slot
    assert not task.complete(world, 1)


# ------------------------------------------------------------------ pursuit-evasion


def pursuit(dists: list[float]) -> tuple[PursuitEvasion, KinematicWorld]:
    task = create("pursuit_evasion", len(dists))
    assert isinstance(task, PursuitEvasion)
    [ev] = task.evaders
    at: dict[str, NE] = {ev: (0.0, 0.0)}
    for k, (p, d) in enumerate(zip(task.pursuers, dists, strict=True)):
        at[p] = [(d, 0.0), (-d, 0.0), (0.0, d)][k]
    return task, world_of(task, at)


def test_pursuit_completes_with_two_pursuers_at_exactly_6_m() -> None:
    task, world = pursuit([6.0, 6.0, 40.0])
    assert task.complete(world, 1)
    assert_ends_on_first_complete_round(task, world)


def test_pursuit_needs_two_pursuers_within_6_m() -> None:
    task, world = pursuit([6.0, 6.0 + 1e-9, 40.0])
    assert not task.complete(world, 1)
    assert_never_completes(task, world)
    task, world = pursuit([1.0, 40.0, 40.0])  # one catcher, however close, is not enough
    assert not task.complete(world, 1)


def test_a_single_pursuer_catches_alone() -> None:
    task, world = pursuit([6.0])
    assert task.complete(world, 1)


# ------------------------------------------------------------------ collection-delivery


def test_collection_completes_when_the_last_treasure_is_delivered() -> None:
    """Pickups and deliveries through the task's own dynamics (mpe2's post_step): the
    collector is put on each treasure, then on the matching deposit."""
    task = create("collection_delivery", 4)
    assert isinstance(task, CollectionDelivery)
    deposits = {"red": (-60.0, -60.0), "blue": (60.0, -60.0)}
    [red, blue] = task.deposits
    world = world_of(task, {red: deposits["red"], blue: deposits["blue"]})
    ep = Episode(task, world)
    collector = world.body(task.collectors[0])
    n = len(task.treasure_ids)
    for k, tid in enumerate(task.treasure_ids):
        colour = task.treasure_colour[tid]
        collector.north, collector.east = task.treasure_pos[tid]
        picked = ep.advance()
        assert task.cargo[collector.id] == colour
        assert (task.picked, picked.metrics["picked"], picked.metrics["carrying"]) == (
            k + 1,
            k + 1,
            1,
        )
        assert not picked.complete
        collector.north, collector.east = deposits[colour]
        delivered = ep.advance()
        assert task.delivered == delivered.metrics["delivered"] == k + 1
        assert task.cargo[collector.id] == ""
        assert delivered.complete == (k + 1 == n)
        assert delivered.done == (k + 1 == n)
    assert ep.result().reason == "complete"
    assert ep.round == 2 * n


# ------------------------------------------------------------------ private communication


def test_private_communication_ends_after_round_3() -> None:
    task = create("private_communication", 2)
    world = world_of(task, {})
    assert [task.complete(world, r) for r in (1, 2, 3, 4)] == [False, False, True, True]
    ep = Episode(task, world)
    assert [ep.advance().done for _ in range(3)] == [False, False, True]
    assert ep.result().reason == "complete"


# ------------------------------------------------------------------ horizon only


@pytest.mark.parametrize("name", ["world_communication", "goal_concealment"])
def test_horizon_only_tasks_never_complete(name: str) -> None:
    task = create(name)
    world = task.build_world(np.random.default_rng(1))
    assert_never_completes(task, world)
