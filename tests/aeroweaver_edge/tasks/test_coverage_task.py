"""Coverage task: seeded layout, roles, sensing, completion flag and metrics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aeroweaver_edge.config import SimConfig
from aeroweaver_edge.tasks import UnknownTask, create
from aeroweaver_edge.tasks.coverage import LANDMARKS_NE, Coverage
from aeroweaver_edge.tasks.layout import spawn_base
from aeroweaver_edge.world.kinematics import KinematicWorld


def world_for(seed: int, n: int = 3) -> tuple[Coverage, KinematicWorld]:
    task = Coverage(n)
    return task, task.build_world(np.random.default_rng(seed), SimConfig(uavs=n))


def snapshot(world: KinematicWorld) -> list[tuple[float, float, float]]:
    return [b.pos for b in world.bodies()] + [e.pos for e in world.entities()]


def test_spawn_is_deterministic_per_seed() -> None:
    assert snapshot(world_for(66001)[1]) == snapshot(world_for(66001)[1])
    assert snapshot(world_for(66001)[1]) != snapshot(world_for(66002)[1])


def test_landmarks_share_one_group_offset() -> None:
    for seed in range(20):
        _, world = world_for(seed)
        pos = [world.entity(f"L{k}").pos for k in range(3)]
        offsets = [(p[0] - n, p[1] - e) for p, (n, e) in zip(pos, LANDMARKS_NE, strict=True)]
        for off in offsets:
            assert off == pytest.approx(offsets[0])
        assert all(abs(c) <= 10.0 for c in offsets[0])
        assert [e.kind for e in world.entities()] == ["landmark"] * 3


def test_uavs_spawn_near_the_authors_row_with_jitter() -> None:
    assert [spawn_base(i) for i in range(3)] == [(-38.0, -29.0), (-24.0, -39.0), (-10.0, -29.0)]
    for seed in range(20):
        _, world = world_for(seed)
        for i, body in enumerate(world.bodies()):
            n, e = spawn_base(i)
            assert abs(body.north - n) <= 4.0
            assert abs(body.east - e) <= 4.0
            assert body.pos[2] == -5.0
            assert body.vel == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("n", [*range(1, 11), 25, 50])
def test_layout_stays_in_arena_without_near_collisions(n: int) -> None:
    for seed in range(10):
        task, world = world_for(seed, n)
        assert world.uav_ids == [f"uav{i}" for i in range(n)]
        for body in world.bodies():
            assert world.in_arena(body.pos)
        for entity in world.entities():
            assert world.in_arena(entity.pos)
        assert world.near_collisions() == 0
        assert task.metrics(world)["near_collisions"] == 0.0
        landmarks = [e.pos for e in world.entities()]
        assert len(landmarks) == n  # N landmarks, as mpe2's simple_spread_v3(N)
        assert (
            min(
                (
                    math.dist(a[:2], b[:2])
                    for i, a in enumerate(landmarks)
                    for b in landmarks[i + 1 :]
                ),
                default=99.0,
            )
            >= 7.0
        )


def test_roles_and_visibility() -> None:
    task, world = world_for(3)
    assert task.roles() == {"uav0": "searcher", "uav1": "searcher", "uav2": "searcher"}
    assert all(b.role == "searcher" for b in world.bodies())
    # From the spawn row (east about -34) the landmarks (east 14..44) are out of 45 m range.
    seen = task.visible(world, "uav1")
    assert {e.id for e in seen} == {"uav0", "uav2"}
    assert all(e.kind == "uav" and e.role == "searcher" for e in seen)
    body = world.body("uav1")
    body.north, body.east = world.entity("L1").pos[:2]
    seen_ids = {e.id for e in task.visible(world, "uav1")}
    assert {"L0", "L1", "L2"} <= seen_ids


def place_on_landmarks(world: KinematicWorld, miss_m: float = 0.0) -> None:
    for i, body in enumerate(world.bodies()):
        n, e, _ = world.entity(f"L{i}").pos
        body.north, body.east = n + miss_m * 0.6, e + miss_m * 0.8


def test_complete_needs_every_landmark_within_3_m() -> None:
    task, world = world_for(5)
    assert not task.complete(world, 1)
    place_on_landmarks(world, 2.999)
    assert task.complete(world, 1)
    metrics = task.metrics(world)
    assert metrics["covered_landmarks"] == 3.0
    assert metrics["landmark_min_dist_m.L0"] == pytest.approx(2.999)
    place_on_landmarks(world, 3.01)
    assert not task.complete(world, 1)
    assert task.metrics(world)["covered_landmarks"] == 0.0
    place_on_landmarks(world)
    world.body("uav2").east += 50.0
    assert not task.complete(world, 1)
    assert task.metrics(world)["covered_landmarks"] == 2.0


def test_fewer_than_three_uavs_use_the_first_authors_landmarks() -> None:
    for n in (1, 2):
        _, world = world_for(4, n)
        _, world3 = world_for(4, 3)
        assert [e.pos for e in world.entities()] == [e.pos for e in world3.entities()][:n]


def test_more_uavs_get_more_landmarks_and_keep_the_authors_three() -> None:
    task, world = world_for(1, 5)
    _, world3 = world_for(1, 3)
    lms = [e.pos for e in world.entities()]
    assert len(lms) == 5
    assert lms[:3] == [e.pos for e in world3.entities()]  # same draws first, extras after
    rewards = task.rewards(world)
    assert list(rewards) == [f"uav{i}" for i in range(5)]
    assert all(math.isfinite(r) and r < 0 for r in rewards.values())


def test_create_and_errors() -> None:
    assert isinstance(create("coverage", 2), Coverage)
    with pytest.raises(UnknownTask, match="known: coverage"):
        create("nope")
    with pytest.raises(ValueError, match="coverage needs 1 to 50 UAVs"):
        Coverage(0)
    with pytest.raises(ValueError, match="coverage needs 1 to 50 UAVs"):
        Coverage(51)
    with pytest.raises(ValueError, match="altitude"):
        Coverage(3).build_world(np.random.default_rng(0), SimConfig(altitude_m=9.0))
    with pytest.raises(ValueError, match="config flies 4 UAVs"):
        Coverage(3).build_world(np.random.default_rng(0), SimConfig(uavs=4))
