from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from typing import Any

import pytest

from aeroweaver_edge.skills import SkillRegistry
from aeroweaver_edge.tasks import TASK_NAMES, get_spec
from commander.activation import DEFAULT_K, HOLD, condition_roles
from commander.harness import plan_for_task, plan_mission
from commander.mission_parser import MissionParseError

ROSTER3 = ["uav0", "uav1", "uav2"]
LLM = Callable[..., Any]
COVER = "Cover the three landmarks with three drones"


async def test_cover_three_landmarks_with_three_drones(registry: SkillRegistry) -> None:
    plan = await plan_mission(COVER, ROSTER3, registry, None)
    assert plan.task == "coverage"
    assert plan.participants == ROSTER3
    assert plan.parse_source == "fallback"
    assert plan.roles_source == "template"
    assert plan.setup_tokens == 0
    assert plan.record is not None
    assert plan.record.uavs == tuple(ROSTER3)
    for a in plan.assignments.values():
        assert a.role == "searcher"
        assert "cover_landmark" in a.skills
        assert a.skills[-1] == HOLD
        assert len(a.skills) <= 9
    assert "cover_landmark" in plan.catalogue
    assert plan.text == COVER


async def test_k_is_passed_through(registry: SkillRegistry) -> None:
    plan = await plan_mission(COVER, ROSTER3, registry, None, k=1)
    assert all(a.skills == ("cover_landmark", HOLD) for a in plan.assignments.values())


async def test_region_and_constraints_reach_the_plan(registry: SkillRegistry) -> None:
    text = "Cover the landmarks in the north-east quadrant with two drones. Avoid collisions."
    plan = await plan_mission(text, ROSTER3, registry, None)
    assert plan.constraints[0] == "operate inside the box north 0..70 m, east 0..70 m"
    assert "Avoid collisions" in plan.constraints
    assert "stay inside the 140 m x 140 m arena" in plan.constraints
    assert all("Stay inside the box" in a.local_goal for a in plan.assignments.values())


async def test_llm_end_to_end_counts_setup_tokens(registry: SkillRegistry, llm: LLM) -> None:
    record = {
        "task": "world_communication",
        "uavs": ROSTER3,
        "role_counts": {"pursuer": 2},
        "region": None,
        "constraints": [],
    }
    roles = {
        "assignments": [
            {"uav": "uav0", "role": "pursuer", "local_goal": "Chase the forager in the north."},
            {"uav": "uav1", "role": "pursuer", "local_goal": "Chase the forager in the south."},
            {"uav": "uav2", "role": "leader", "local_goal": "Spot foragers and report them."},
        ]
    }
    fp, client = await llm([json.dumps(record), json.dumps(roles)])
    text = "The leader drone spots the foragers and tells two pursuers where they are."
    plan = await plan_mission(text, ROSTER3, registry, client)
    assert plan.parse_source == "llm"
    assert plan.roles_source == "llm"
    assert plan.assignments["uav2"].role == "leader"
    assert "signal_target" in plan.assignments["uav2"].skills
    assert "signal_target" not in plan.assignments["uav0"].skills
    assert plan.setup_tokens > 0
    assert plan.setup_tokens == client.ledger.total.total_tokens
    assert [e.tag.purpose for e in client.ledger.journal] == ["mission_parse", "role_assign"]
    roles_prompt = fp.chat_bodies()[1]["messages"][0]["content"]
    assert all(f"- {s}:" in roles_prompt for s in plan.catalogue)  # catalogue docs in context


async def test_llm_down_falls_back_and_skips_the_role_call(
    registry: SkillRegistry, llm: LLM
) -> None:
    fp, client = await llm([500])
    plan = await plan_mission(COVER, ROSTER3, registry, client)
    assert plan.parse_source == "fallback"
    assert plan.roles_source == "template"
    assert fp.served == 1  # no role call after the endpoint failed
    assert any("HTTP 500" in n for n in plan.notes)
    assert any("roles: LLM skipped" in n for n in plan.notes)
    assert all(a.role == "searcher" for a in plan.assignments.values())


async def test_garbage_parse_still_tries_llm_roles(registry: SkillRegistry, llm: LLM) -> None:
    fp, client = await llm(["not json", "still not json"])
    plan = await plan_mission(COVER, ROSTER3, registry, client)
    assert plan.parse_source == "fallback"
    assert plan.roles_source == "template"
    assert fp.served == 2
    assert plan.setup_tokens == client.ledger.total.total_tokens > 0


async def test_unparsable_mission_raises(registry: SkillRegistry) -> None:
    with pytest.raises(MissionParseError, match="asked for 5 drones but only 3 are up"):
        await plan_mission("Cover the landmarks with 5 drones.", ROSTER3, registry, None)


@pytest.mark.parametrize("task", TASK_NAMES)
def test_a_plan_from_the_task_name_activates_per_role_without_llm(
    task: str, registry: SkillRegistry
) -> None:
    """``aeroweaver sim <task>``: record from the task name, template roles, top-K
    retrieval; every role gets at least one of its own skills, stationary roles only theirs."""
    spec = get_spec(task)
    uavs = [f"uav{i}" for i in range(spec.team_size)]
    plan = plan_for_task(task, uavs, registry, mission_id="m1")
    assert plan.record is not None
    assert plan.record.task == task
    assert plan.text == spec.mission_text
    assert (plan.parse_source, plan.roles_source, plan.setup_tokens) == ("template", "template", 0)
    assert plan.participants == uavs
    counts = spec.role_counts(len(uavs))
    assert Counter(a.role for a in plan.assignments.values()) == +Counter(counts)
    for a in plan.assignments.values():
        assert a.skills[-1] == "hold_position"
        assert len(a.skills) <= DEFAULT_K + 1
        active = [s for s in a.skills if s != HOLD]
        assert active, f"{task}/{a.role} got no task skill"
        for s in active:
            roles = condition_roles(registry.get(s).doc.conditions)
            assert roles is None or a.role in roles, f"{task}/{a.role} got {s}"
            if spec.role(a.role).stationary:
                assert roles is not None, f"stationary {a.role} got the open skill {s}"
