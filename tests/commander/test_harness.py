from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import pytest

from aeroweaver_edge.skills import SkillRegistry
from commander.activation import HOLD
from commander.harness import plan_mission
from commander.mission_parser import MissionParseError
from commander.plan import COVERAGE_SKILLS, template_plan

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


def test_template_plan_still_works() -> None:
    plan = template_plan("coverage", ROSTER3, "m1")
    assert plan.assignments["uav0"].skills == COVERAGE_SKILLS
    assert plan.record is None
    assert plan.parse_source == "template"
