"""The coverage skills' executors on hand-made observations: pure Intents, no side effects."""

from __future__ import annotations

import math

import pytest

from aeroweaver_edge.contracts.actions import HOLD, Hold, Intent, MoveTo, Outgoing
from aeroweaver_edge.contracts.observation import Observation, VehicleState
from aeroweaver_edge.contracts.skill_api import SkillContext
from aeroweaver_edge.contracts.wire import Entity
from aeroweaver_edge.skills import Skill, SkillRegistry, load_skills


@pytest.fixture(scope="module")
def reg() -> SkillRegistry:
    return load_skills()


def obs(*entities: Entity, round_: int = 0) -> Observation:
    own = VehicleState(pos=(-30.0, -30.0, -5.0), vel=(0.0, 0.0, 0.0))
    return Observation(uav="u1", episode=0, round=round_, own=own, entities=entities)


def ctx(uav_index: int = 1, altitude_m: float = 5.0, **settings: float) -> SkillContext:
    return SkillContext(
        uav="u1",
        uav_index=uav_index,
        role="searcher",
        task="coverage",
        altitude_m=altitude_m,
        settings=dict(settings),
    )


L1 = Entity(id="L1", kind="landmark", pos=(-28.0, 24.0, 0.0))
L2 = Entity(id="L2", kind="landmark", pos=(4.0, 34.0, 0.0))
PEER = Entity(id="u2", kind="uav", pos=(0.0, 0.0, -5.0))
FOOD = Entity(id="F1", kind="food", pos=(25.0, 25.0, 0.0))


def run(skill: Skill, o: Observation, c: SkillContext, **params: object) -> Intent:
    return skill.execute(skill.parse_params(params), o, c)


# ------------------------------------------------------------------ cover_landmark


def test_cover_landmark_offers_one_option_per_visible_landmark(reg: SkillRegistry) -> None:
    skill = reg.get("cover_landmark")
    opts = skill.options(obs(L1, PEER, FOOD, L2), ctx())
    assert [skill.invocation(p) for p in opts] == [
        "cover_landmark(target_id=L1)",
        "cover_landmark(target_id=L2)",
    ]
    assert skill.options(obs(PEER, FOOD), ctx()) == []


def test_a_crowded_view_offers_the_nearest_eight_in_observation_order(
    reg: SkillRegistry,
) -> None:
    """50 UAVs mean 50 landmarks: only the nearest eight become options (the label budget is
    26 for everything), in the order they were observed; ``max_targets`` overrides."""
    skill = reg.get("cover_landmark")
    # Own position (-30, -30); landmark k is 5 k m away along north, listed far to near.
    lms = [
        Entity(id=f"L{k}", kind="landmark", pos=(-30.0 + 5.0 * k, -30.0, 0.0)) for k in range(12)
    ]
    opts = skill.options(obs(*reversed(lms)), ctx())
    assert [p.model_dump()["target_id"] for p in opts] == [f"L{k}" for k in range(7, -1, -1)]
    few = skill.options(obs(*lms), ctx(max_targets=3))
    assert [p.model_dump()["target_id"] for p in few] == ["L0", "L1", "L2"]


def test_cover_landmark_moves_over_the_landmark_at_own_altitude(reg: SkillRegistry) -> None:
    intent = run(reg.get("cover_landmark"), obs(L1, L2), ctx(altitude_m=7.5), target_id="L2")
    assert intent.motion == MoveTo((4.0, 34.0, -7.5))
    assert intent.messages == (
        Outgoing(
            to="*",
            kind="intent",
            body={"skill": "cover_landmark", "target_id": "L2", "north": 4.0, "east": 34.0},
        ),
    )


def test_cover_landmark_holds_when_target_not_visible(reg: SkillRegistry) -> None:
    skill = reg.get("cover_landmark")
    assert run(skill, obs(L1), ctx(), target_id="L2") == HOLD
    assert run(skill, obs(), ctx(), target_id="L1") == HOLD


def test_cover_landmark_holds_when_target_is_not_a_landmark(reg: SkillRegistry) -> None:
    assert run(reg.get("cover_landmark"), obs(L1, PEER), ctx(), target_id="u2") == HOLD


def test_cover_landmark_option_round_trips_through_its_invocation(reg: SkillRegistry) -> None:
    skill = reg.get("cover_landmark")
    [option] = skill.options(obs(L1), ctx())
    assert skill.parse_params(option.model_dump()) == option
    assert skill.execute(option, obs(L1), ctx()).motion == MoveTo((-28.0, 24.0, -5.0))


# ------------------------------------------------------------------ explore_local


@pytest.mark.parametrize(("round_", "index"), [(0, 0), (9, 1), (23, 2), (120, 9)])
def test_explore_local_waypoint_follows_the_authors_rule(
    reg: SkillRegistry, round_: int, index: int
) -> None:
    skill = reg.get("explore_local")
    o, c = obs(round_=round_), ctx(uav_index=index)
    [option] = skill.options(o, c)
    intent = skill.execute(option, o, c)
    angle = round_ / 18 + 1.7 * index
    expected = (35.0 * math.cos(angle), 35.0 * math.sin(angle), -5.0)
    assert isinstance(intent.motion, MoveTo)
    assert intent.motion.target == pytest.approx(expected)
    assert math.hypot(*intent.motion.target[:2]) == pytest.approx(35.0)
    [msg] = intent.messages
    assert msg.kind == "intent"
    assert msg.body["skill"] == "explore_local"
    # The message carries the waypoint to 0.1 m (compact prompts); the motion keeps it exact.
    assert (msg.body["north"], msg.body["east"]) == (round(expected[0], 1), round(expected[1], 1))


def test_explore_local_spreads_uavs_apart(reg: SkillRegistry) -> None:
    skill = reg.get("explore_local")
    targets = []
    for index in range(3):
        intent = run(skill, obs(round_=4), ctx(uav_index=index))
        assert isinstance(intent.motion, MoveTo)
        targets.append(intent.motion.target)
    gaps = [math.dist(a, b) for i, a in enumerate(targets) for b in targets[i + 1 :]]
    assert min(gaps) > 20.0


def test_explore_local_respects_an_offset_arena_centre(reg: SkillRegistry) -> None:
    c = ctx(uav_index=0, arena_centre_north=100.0, arena_centre_east=-50.0)
    intent = run(reg.get("explore_local"), obs(), c)
    assert intent.motion == MoveTo((135.0, -50.0, -5.0))


# ------------------------------------------------------------------ return / hold


def test_return_in_bounds_goes_to_the_origin(reg: SkillRegistry) -> None:
    skill = reg.get("return_in_bounds")
    o = obs(L1)
    assert [skill.invocation(p) for p in skill.options(o, ctx())] == ["return_in_bounds()"]
    intent = run(skill, o, ctx(altitude_m=6.0))
    assert intent.motion == MoveTo((0.0, 0.0, -6.0))
    assert [m.kind for m in intent.messages] == ["intent"]


def test_hold_position_holds_without_messages(reg: SkillRegistry) -> None:
    skill = reg.get("hold_position")
    intent = run(skill, obs(L1, PEER), ctx())
    assert intent.motion == Hold()
    assert intent.messages == ()


@pytest.mark.parametrize("name", ["explore_local", "return_in_bounds", "hold_position"])
def test_always_available_skills_offer_one_option_on_an_empty_view(
    reg: SkillRegistry, name: str
) -> None:
    skill = reg.get(name)
    assert skill.options(obs(), ctx()) == [skill.parse_params({})]
    with pytest.raises(ValueError, match="unknown parameter"):
        skill.parse_params({"target_id": "L1"})


@pytest.mark.parametrize(
    ("name", "params"),
    [
        ("cover_landmark", {"target_id": "L1"}),
        ("explore_local", {}),
        ("return_in_bounds", {}),
        ("hold_position", {}),
    ],
)
def test_executors_are_pure(reg: SkillRegistry, name: str, params: dict[str, object]) -> None:
    skill = reg.get(name)
    o, c = obs(L1, PEER, round_=5), ctx()
    first = run(skill, o, c, **params)
    assert run(skill, o, c, **params) == first
    assert o.memo == {}
    assert first.memo == {}
