from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from typing import Any

import pytest

from aeroweaver_edge.tasks import specs
from commander.roles import RoleError, RolePlan, assign_roles, check_roles, template_roles
from commander.task_record import TaskRecord

ROSTER = [f"uav{i}" for i in range(10)]


def _record(task: str, n: int | None = None, **kw: Any) -> TaskRecord:
    n = specs()[task].team_size if n is None else n
    return TaskRecord.model_validate(
        {"task": task, "uavs": ROSTER[:n], "text": "mission", **kw}, context={"roster": ROSTER}
    )


DEFAULTS = {
    "coverage": {"searcher": 3},
    "pursuit_evasion": {"pursuer": 3},
    "guided_navigation": {"speaker": 1, "listener": 1},
    "private_communication": {"sender": 1, "receiver": 1},
    "circular_formation": {"member": 5},
    "line_formation": {"member": 5},
    "world_communication": {"leader": 1, "pursuer": 2},
    "collection_delivery": {"collector": 2, "deposit_red": 1, "deposit_blue": 1},
    "goal_concealment": {"informed": 2},
}


@pytest.mark.parametrize("task", list(specs()))
def test_templates_match_the_default_roles_table(task: str) -> None:
    roles = template_roles(_record(task))
    assert Counter(a.role for a in roles.values()) == DEFAULTS[task]
    assert all(a.local_goal.endswith(".") for a in roles.values())
    spec = specs()[task]
    assert all(a.local_goal.startswith(spec.role(a.role).goal) for a in roles.values())


def test_template_honours_stated_counts_and_region() -> None:
    rec = _record(
        "guided_navigation",
        3,
        role_counts={"listener": 2},
        region={"kind": "circle", "north_m": 0, "east_m": 0, "radius_m": 20},
    )
    roles = template_roles(rec)
    assert Counter(a.role for a in roles.values()) == {"speaker": 1, "listener": 2}
    assert all("Stay within 20 m of north 0 m, east 0 m." in a.local_goal for a in roles.values())
    rec = _record("collection_delivery", 3, role_counts={"collector": 2})
    assert Counter(a.role for a in template_roles(rec).values()) == {
        "collector": 2,
        "deposit_red": 1,
    }


def _plan(*rows: tuple[str, str]) -> RolePlan:
    return RolePlan.model_validate(
        {"assignments": [{"uav": u, "role": r, "local_goal": "go."} for u, r in rows]}
    )


def test_check_roles_accepts_a_fitting_plan() -> None:
    rec = _record("world_communication")
    out = check_roles(_plan(("uav0", "pursuer"), ("uav1", "leader"), ("uav2", "pursuer")), rec)
    assert out["uav1"].role == "leader"


@pytest.mark.parametrize(
    ("rows", "message"),
    [
        (
            (("uav0", "leader"), ("uav1", "chaser"), ("uav2", "pursuer")),
            "roles not in world_communication: chaser",
        ),
        ((("uav0", "leader"), ("uav1", "leader"), ("uav2", "pursuer")), "leader: 2 assigned"),
        ((("uav0", "leader"), ("uav1", "pursuer")), "UAVs without a role: uav2"),
        (
            (("uav0", "leader"), ("uav1", "pursuer"), ("uav2", "pursuer"), ("uav2", "pursuer")),
            "more than one role: uav2",
        ),
        (
            (("uav0", "leader"), ("uav1", "pursuer"), ("uav2", "pursuer"), ("uav7", "pursuer")),
            "not in the mission: uav7",
        ),
    ],
)
def test_check_roles_rejects(rows: tuple[tuple[str, str], ...], message: str) -> None:
    with pytest.raises(RoleError, match=message):
        check_roles(_plan(*rows), _record("world_communication"))


def test_check_roles_enforces_stated_counts() -> None:
    rec = _record("guided_navigation", 3, role_counts={"listener": 2})
    with pytest.raises(RoleError, match="listener: 1 assigned but the mission asks for 2"):
        check_roles(_plan(("uav0", "speaker"), ("uav1", "listener"), ("uav2", "speaker")), rec)


LLM = Callable[..., Any]


def _answer(*rows: tuple[str, str]) -> str:
    return json.dumps(
        {"assignments": [{"uav": u, "role": r, "local_goal": f"{r} goal."} for u, r in rows]}
    )


async def test_llm_roles_accepted(llm: LLM) -> None:
    fp, client = await llm([_answer(("uav0", "speaker"), ("uav1", "listener"))])
    out = await assign_roles(_record("guided_navigation"), [], client)
    assert out.source == "llm"
    assert out.tokens > 0
    assert out.assignments["uav0"].local_goal == "speaker goal."
    body = fp.chat_bodies()[0]
    assert body["response_format"]["json_schema"]["name"] == "role_plan"
    assert "speaker" in body["messages"][0]["content"]


@pytest.mark.parametrize(
    ("answer", "reason"),
    [
        (_answer(("uav0", "speaker"), ("uav1", "navigator")), "roles not in guided_navigation"),
        (_answer(("uav0", "speaker"), ("uav1", "speaker")), "speaker: 2 assigned"),
        ('{"assignments": []}', "field 'assignments'"),
        ("no JSON here", "no JSON object"),
        (503, "LLMHTTPError"),
    ],
)
async def test_bad_llm_roles_fall_back_to_template(
    llm: LLM, answer: str | int, reason: str
) -> None:
    _, client = await llm([answer])
    out = await assign_roles(_record("guided_navigation"), [], client)
    assert out.source == "template"
    assert Counter(a.role for a in out.assignments.values()) == {"speaker": 1, "listener": 1}
    assert any(reason in n and "role template" in n for n in out.notes)


async def test_no_client_or_skip_uses_template() -> None:
    out = await assign_roles(_record("coverage"), [], None)
    assert out.source == "template"
    assert out.tokens == 0
