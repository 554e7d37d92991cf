"""The Commander's harness on the real embedded model: structure only.

SmolLM2-135M has no judgement; whatever it answers, the harness must return a valid plan
(from the LLM or, after a rejected answer, from the fallback) and count setup tokens.
"""

from __future__ import annotations

import pytest

from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.llm.embedded import EmbeddedServer
from aeroweaver_edge.skills import load_skills
from commander.harness import plan_mission


@pytest.mark.embedded
@pytest.mark.slow
@pytest.mark.timeout(900)  # two generations of a JSON record; minutes on a loaded 2-core box
async def test_plan_mission_on_the_embedded_model() -> None:
    roster = ["uav0", "uav1", "uav2"]
    async with EmbeddedServer() as server:
        # A generous deadline: the assertion is about structure, not speed, and a loaded
        # machine (CI neighbours) must not turn every call into a timeout.
        client = ChatClient(server.base_url, server.model, deadline_s=300.0)
        async with client:
            plan = await plan_mission(
                "Cover the three landmarks with three drones", roster, load_skills(), client
            )
    assert plan.task == "coverage"
    assert plan.record is not None
    assert sorted(plan.record.uavs) == roster
    assert plan.parse_source in {"llm", "fallback"}
    assert plan.roles_source in {"llm", "template"}
    assert plan.setup_tokens > 0  # the calls were made and counted, whatever they answered
    for a in plan.assignments.values():
        assert a.role == "searcher"
        assert "cover_landmark" in a.skills
        assert a.skills[-1] == "hold_position"
