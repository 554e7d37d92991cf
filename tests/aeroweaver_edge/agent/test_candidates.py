"""Candidate enumeration: labels in activation order, dedup, label budget, unknown skills."""

from __future__ import annotations

import pytest

from aeroweaver_edge.agent.candidates import LABELS, build_candidates
from aeroweaver_edge.contracts.observation import Observation, VehicleState
from aeroweaver_edge.contracts.skill_api import SkillContext
from aeroweaver_edge.contracts.wire import Entity
from aeroweaver_edge.skills import SkillRegistry, load_skills

CTX = SkillContext(uav="uav0", uav_index=0, role="searcher", task="coverage")
# cover_landmark offers the nearest eight landmarks by default; the budget tests need more.
WIDE = SkillContext(
    uav="uav0", uav_index=0, role="searcher", task="coverage", settings={"max_targets": 100.0}
)


@pytest.fixture(scope="module")
def reg() -> SkillRegistry:
    return load_skills()


def landmark(i: int, north: float = 10.0) -> Entity:
    return Entity(id=f"L{i}", kind="landmark", pos=(north, float(i), -5.0))


def obs(*entities: Entity) -> Observation:
    own = VehicleState(pos=(0.0, 0.0, -5.0), vel=(0.0, 0.0, 0.0))
    return Observation(uav="uav0", episode=0, round=3, own=own, entities=entities)


def test_labels_follow_activation_order(reg: SkillRegistry) -> None:
    o = obs(landmark(0), landmark(1))
    cs = build_candidates(reg, ["hold_position", "cover_landmark", "explore_local"], o, CTX)
    assert cs.labels == ["A", "B", "C", "D"]
    assert [c.text for c in cs.candidates] == [
        "hold_position()",
        "cover_landmark(target_id=L0)",
        "cover_landmark(target_id=L1)",
        "explore_local()",
    ]
    assert cs.overflow == 0

    flipped = build_candidates(reg, ["explore_local", "cover_landmark", "hold_position"], o, CTX)
    assert [(c.label, c.skill) for c in flipped.candidates] == [
        ("A", "explore_local"),
        ("B", "cover_landmark"),
        ("C", "cover_landmark"),
        ("D", "hold_position"),
    ]


def test_params_by_label_are_the_validated_models(reg: SkillRegistry) -> None:
    cs = build_candidates(reg, ["cover_landmark", "hold_position"], obs(landmark(7)), CTX)
    a, b = cs.candidates
    assert (a.skill, a.params) == ("cover_landmark", {"target_id": "L7"})
    assert (b.skill, b.params) == ("hold_position", {})
    assert cs.params["A"].model_dump() == {"target_id": "L7"}
    assert isinstance(cs.params["A"], reg.get("cover_landmark").params)
    assert set(cs.params) == {"A", "B"}


def test_duplicate_options_and_skills_are_listed_once(reg: SkillRegistry) -> None:
    o = obs(landmark(0), landmark(0), landmark(1))  # L0 sensed twice
    cs = build_candidates(
        reg, ["cover_landmark", "hold_position", "cover_landmark", "hold_position"], o, CTX
    )
    assert [c.text for c in cs.candidates] == [
        "cover_landmark(target_id=L0)",
        "cover_landmark(target_id=L1)",
        "hold_position()",
    ]
    assert cs.labels == ["A", "B", "C"]


def test_unknown_skill_names_are_skipped(reg: SkillRegistry) -> None:
    cs = build_candidates(reg, ["fly_to_the_moon", "hold_position", "ARM_NOW"], obs(), CTX)
    assert [(c.label, c.text) for c in cs.candidates] == [("A", "hold_position()")]
    assert cs.overflow == 0


def test_skills_with_no_option_now_add_nothing(reg: SkillRegistry) -> None:
    cs = build_candidates(reg, ["cover_landmark"], obs(), CTX)  # nothing visible
    assert cs.candidates == ()
    assert cs.overflow == 0


def test_exactly_the_label_budget_is_allowed(reg: SkillRegistry) -> None:
    o = obs(*(landmark(i) for i in range(len(LABELS) - 1)))
    cs = build_candidates(reg, ["cover_landmark", "hold_position"], o, WIDE)
    assert len(cs.candidates) == len(LABELS) == 26
    assert cs.labels[-1] == "Z"
    assert cs.candidates[-1].text == "hold_position()"
    assert cs.overflow == 0


def test_overflow_beyond_26_labels_is_an_empty_set(reg: SkillRegistry) -> None:
    o = obs(*(landmark(i) for i in range(30)))
    cs = build_candidates(reg, ["cover_landmark", "hold_position"], o, WIDE)
    assert cs.candidates == ()
    assert cs.params == {}
    assert cs.overflow == 31 - 26


def test_overflow_beyond_a_smaller_model_budget(reg: SkillRegistry) -> None:
    o = obs(landmark(0), landmark(1), landmark(2))
    full = ["cover_landmark", "hold_position"]
    assert len(build_candidates(reg, full, o, CTX, max_labels=4).candidates) == 4
    cs = build_candidates(reg, full, o, CTX, max_labels=3)
    assert (cs.candidates, cs.overflow) == ((), 1)


def test_budget_never_exceeds_the_alphabet(reg: SkillRegistry) -> None:
    o = obs(*(landmark(i) for i in range(27)))
    cs = build_candidates(reg, ["cover_landmark"], o, WIDE, max_labels=100)
    assert (cs.candidates, cs.overflow) == ((), 1)
