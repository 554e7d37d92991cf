from __future__ import annotations

import pytest

from aeroweaver_edge.skills import SkillRegistry
from commander.activation import (
    HOLD,
    activate,
    condition_roles,
    pack,
    role_allows,
    task_catalogue,
)
from commander.mission_parser import parse_fallback
from commander.retrieval import BM25Retriever
from commander.roles import RoleAssignment, template_roles

ROSTER = [f"uav{i}" for i in range(10)]


@pytest.mark.parametrize(
    ("conditions", "roles"),
    [
        (["role is pursuer or leader", "target visible"], {"pursuer", "leader"}),
        (
            ["role is deposit_<colour> (deposit_red or deposit_blue)"],
            {"deposit_red", "deposit_blue"},
        ),
        (["roles: pursuer, leader"], {"pursuer", "leader"}),
        (["Role is member"], {"member"}),
        (["the landmark is within sensing range"], None),
        (["roles: any"], set()),
        (["roles: all"], None),
    ],
)
def test_condition_roles(conditions: list[str], roles: set[str] | None) -> None:
    got = condition_roles(conditions)
    assert (got is None and roles is None) or got == roles


def test_pack_concatenates_mission_role_goal() -> None:
    assert (
        pack(" Chase it. ", "pursuer", "Catch. ") == "Chase it.\nRole: pursuer\nLocal goal: Catch."
    )


def _activate(
    registry: SkillRegistry, text: str, k: int = 8, catalogue_size: int = 12
) -> dict[str, tuple[str, ...]]:
    rec = parse_fallback(text, ROSTER)
    r = BM25Retriever(registry.documents())
    cat = task_catalogue(r, rec, catalogue_size)
    return activate(r, registry, text, rec, template_roles(rec), cat, k)


@pytest.mark.parametrize("k", [0, 1, 3, 8])
def test_hold_always_last_and_k_respected(registry: SkillRegistry, k: int) -> None:
    out = _activate(registry, "The leader tells two pursuers where the foragers are.", k)
    for skills in out.values():
        assert skills[-1] == HOLD
        assert skills.count(HOLD) == 1
        assert len(skills) <= k + 1
    if k == 0:
        assert all(s == (HOLD,) for s in out.values())


def test_role_conditions_are_respected(registry: SkillRegistry) -> None:
    text = "The leader spots the foragers and tells two pursuers where they are; catch them."
    rec = parse_fallback(text, ROSTER)
    roles = template_roles(rec)
    out = _activate(registry, text, k=8, catalogue_size=27)
    for uav, skills in out.items():
        for s in skills:
            assert role_allows(registry, s, roles[uav].role, stationary=False), (uav, s)
    leader = next(u for u, a in roles.items() if a.role == "leader")
    pursuers = [u for u, a in roles.items() if a.role == "pursuer"]
    assert "signal_target" in out[leader]
    assert all("signal_target" not in out[p] for p in pursuers)  # leader-only skill
    assert all("evade_peer" not in s and "seek_food" not in s for s in out.values())  # foragers'


def test_stationary_roles_get_only_their_own_skills(registry: SkillRegistry) -> None:
    out = _activate(
        registry, "Send a secret message from the sender to the receiver.", k=8, catalogue_size=27
    )
    for skills in out.values():
        for s in skills[:-1]:
            roles = condition_roles(registry.get(s).doc.conditions)
            assert roles is not None, s
            assert roles & {"sender", "receiver"}, s
    assert set(out["uav0"]) == {"encode_message", HOLD}
    assert set(out["uav1"]) == {"decode_message", HOLD}


def test_different_roles_get_different_subsets(registry: SkillRegistry) -> None:
    text = "Collect the treasures and deliver each one to the deposit of its colour."
    rec = parse_fallback(text, ROSTER)
    out = _activate(registry, text)
    by_role = {template_roles(rec)[u].role: set(s) for u, s in out.items()}
    assert "collect_treasure" in by_role["collector"]
    assert "collect_treasure" not in by_role["deposit_red"]


def test_unknown_role_gets_only_open_skills(registry: SkillRegistry) -> None:
    rec = parse_fallback("Cover the landmarks with three drones.", ROSTER)
    r = BM25Retriever(registry.documents())
    out = activate(
        r,
        registry,
        rec.text,
        rec,
        {"uav0": RoleAssignment("tourist", "look")},
        list(registry.names()),
        27,
    )
    assert all(condition_roles(registry.get(s).doc.conditions) is None for s in out["uav0"])


def test_negative_k_refused(registry: SkillRegistry) -> None:
    rec = parse_fallback("Cover the landmarks.", ROSTER)
    r = BM25Retriever(registry.documents())
    with pytest.raises(ValueError, match="k must be"):
        activate(r, registry, rec.text, rec, template_roles(rec), [], -1)
