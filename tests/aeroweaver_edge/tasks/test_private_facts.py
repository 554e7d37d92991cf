"""Private facts are role-restricted: a body perceives its own role's facts and never another
role's, in every task; the entities facts name are perceived only by their holders."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aeroweaver_edge import tasks
from aeroweaver_edge.tasks.base import TaskDefinition
from aeroweaver_edge.world.kinematics import KinematicWorld

ALL_FACTS = {f for spec in tasks.specs().values() for r in spec.all_roles for f in r.facts}


def sizes(name: str) -> list[int]:
    spec = tasks.get_spec(name)
    return sorted({spec.team_size, min(spec.max_uavs, spec.team_size + 3)})


@pytest.mark.parametrize("name", tasks.TASK_NAMES)
def test_each_body_gets_exactly_its_roles_facts(name: str) -> None:
    for n in sizes(name):
        task = tasks.create(name, n)
        for seed in range(5):
            world = task.build_world(np.random.default_rng(seed))
            for body in task.body_ids:
                own = set(task.spec.role(task.role_of(body)).facts)
                facts = task.private_facts(world, body)
                assert set(facts) == own, (name, body)
                assert not (set(facts) & (ALL_FACTS - own))
                assert all(isinstance(v, str) and len(v) <= 64 for v in facts.values())


def test_subclass_facts_cannot_leak_past_the_role_filter() -> None:
    """The concealment task hands the goal to *every* body; the role filter keeps it from
    the adversary, whose role declares no facts."""
    task = tasks.create("goal_concealment", 2)
    world = task.build_world(np.random.default_rng(0))
    assert task.facts(world, "adversary0") == {"goal_landmark": task.goal}  # type: ignore[attr-defined]
    assert task.private_facts(world, "adversary0") == {}


def far_from(world: KinematicWorld, body: str, entity: str) -> None:
    p = world.entity(entity).pos
    b = world.body(body)
    b.north, b.east = -p[0] if abs(p[0]) > 10 else 60.0, -p[1] if abs(p[1]) > 10 else -60.0
    assert math.hypot(b.north - p[0], b.east - p[1]) > 45.0


def ids(task: TaskDefinition, world: KinematicWorld, body: str) -> set[str]:
    return {e.id for e in task.visible(world, body)}


def test_only_the_speaker_perceives_the_goal_from_afar() -> None:
    task = tasks.create("guided_navigation", 3)
    world = task.build_world(np.random.default_rng(2))
    goal = task.goal  # type: ignore[attr-defined]
    speaker, *listeners = task.uav_ids
    for body in task.uav_ids:
        far_from(world, body, goal)
    assert goal in ids(task, world, speaker)
    for lid in listeners:
        assert goal not in ids(task, world, lid)
        assert task.private_facts(world, lid) == {}


def test_only_informed_uavs_perceive_the_concealed_goal() -> None:
    task = tasks.create("goal_concealment", 2)
    world = task.build_world(np.random.default_rng(3))
    goal = task.goal  # type: ignore[attr-defined]
    for body in task.body_ids:
        far_from(world, body, goal)
    assert all(goal in ids(task, world, u) for u in task.uav_ids)
    assert goal not in ids(task, world, "adversary0")


def test_a_member_perceives_its_own_slot_but_not_the_others_from_afar() -> None:
    task = tasks.create("line_formation", 6)
    world = task.build_world(np.random.default_rng(4))
    body = world.body("uav2")
    body.north, body.east = -69.0, -69.0
    seen = ids(task, world, "uav2")
    assert "S2" in seen
    assert not ({"S0", "S1", "S3", "S4", "S5"} & seen)


def test_symbol_and_key_stay_with_sender_and_receiver() -> None:
    task = tasks.create("private_communication", 2)
    for seed in range(8):
        world = task.build_world(np.random.default_rng(seed))
        sender, receiver = task.uav_ids
        s, r = task.private_facts(world, sender), task.private_facts(world, receiver)
        assert s["key"] == r["key"]
        assert "private_symbol" not in r
        assert task.private_facts(world, "eavesdropper0") == {}


def test_cargo_is_the_collectors_own() -> None:
    task = tasks.create("collection_delivery", 4)
    world = task.build_world(np.random.default_rng(0))
    collector = task.uav_ids[0]
    task.cargo[collector] = "blue"  # type: ignore[attr-defined]
    assert task.private_facts(world, collector) == {"cargo": "blue"}
    assert task.private_facts(world, task.uav_ids[1]) == {"cargo": ""}
    assert all(task.private_facts(world, d) == {} for d in task.uav_ids[2:])
