"""The scripted scorer on coverage: a normalised distribution over exactly the candidate
labels, and (coverage's reference policy) a preference for the nearest landmark no other UAV
is better placed to take."""

from __future__ import annotations

import dataclasses
import math

import pytest

from aeroweaver_edge.agent.candidates import build_candidates
from aeroweaver_edge.agent.scoring import LabelScores, choose
from aeroweaver_edge.agent.scripted import ReferenceScorer
from aeroweaver_edge.contracts.observation import Observation, VehicleState
from aeroweaver_edge.contracts.ports import DecisionRequest
from aeroweaver_edge.contracts.skill_api import SkillContext
from aeroweaver_edge.contracts.wire import Entity, Header, InboxMessage, Vec3
from aeroweaver_edge.skills import SkillRegistry, load_skills

CTX = SkillContext(uav="uav0", uav_index=0, role="searcher", task="coverage")
ACTIVE = ["cover_landmark", "explore_local", "return_in_bounds", "hold_position"]
L_NEAR = Entity(id="L0", kind="landmark", pos=(10.0, 0.0, -5.0))
L_FAR = Entity(id="L1", kind="landmark", pos=(0.0, 30.0, -5.0))


@pytest.fixture(scope="module")
def reg() -> SkillRegistry:
    return load_skills()


def intent_from(sender: str, pos: Vec3) -> InboxMessage:
    return InboxMessage(
        h=Header(sender=sender, epoch=1, seq=1, stamp=0.0),
        to="uav0",
        round=2,
        kind="intent",
        body={"skill": "cover_landmark"},
        sender_pos=pos,
    )


def request(
    reg: SkillRegistry,
    *entities: Entity,
    pos: Vec3 = (0.0, 0.0, -5.0),
    messages: tuple[InboxMessage, ...] = (),
) -> DecisionRequest:
    o = Observation(
        uav="uav0",
        episode=0,
        round=3,
        own=VehicleState(pos, (0.0, 0.0, 0.0)),
        entities=entities,
        messages=messages,
    )
    cs = build_candidates(reg, ACTIVE, o, CTX)
    return DecisionRequest(
        observation=o,
        mission_text="cover",
        role="searcher",
        local_goal="cover one",
        constraints=(),
        skill_docs=(),
        observation_text="",
        candidates=cs.candidates,
        task="coverage",
    )


async def pick(req: DecisionRequest, scorer: ReferenceScorer | None = None) -> str:
    scores = await (scorer or ReferenceScorer()).score(req)
    choice = choose(scores, [c.label for c in req.candidates], {}, beta=0.0)
    assert choice.label is not None
    return next(c.text for c in req.candidates if c.label == choice.label)


def assert_distribution(scores: LabelScores, req: DecisionRequest) -> None:
    assert set(scores.logprobs) == {c.label for c in req.candidates}
    assert all(lp <= 0.0 and math.isfinite(lp) for lp in scores.logprobs.values())
    assert math.fsum(math.exp(lp) for lp in scores.logprobs.values()) == pytest.approx(1.0)
    assert scores.logprobs_usable
    assert scores.error is None


async def test_scores_are_a_normalised_distribution_over_the_labels(reg: SkillRegistry) -> None:
    for req in (
        request(reg, L_NEAR, L_FAR),
        request(reg),
        request(reg, pos=(68.0, 0.0, -5.0)),
        request(reg, L_NEAR, Entity(id="uav1", kind="uav", pos=(9.0, 0.0, -5.0))),
    ):
        assert_distribution(await ReferenceScorer().score(req), req)


async def test_no_candidates_gives_no_labels(reg: SkillRegistry) -> None:
    req = request(reg)
    empty = dataclasses.replace(req, candidates=())
    scores = await ReferenceScorer().score(empty)
    assert scores.logprobs == {}
    assert choose(scores, [], {}, 0.0).label is None


async def test_prefers_the_nearest_landmark(reg: SkillRegistry) -> None:
    assert await pick(request(reg, L_FAR, L_NEAR)) == "cover_landmark(target_id=L0)"


async def test_leaves_the_nearest_landmark_to_a_closer_peer(reg: SkillRegistry) -> None:
    peer = Entity(id="uav1", kind="uav", pos=(9.0, 1.0, -5.0))  # closer to L0 than we are
    assert await pick(request(reg, L_NEAR, L_FAR, peer)) == "cover_landmark(target_id=L1)"


async def test_keeps_the_nearest_landmark_when_the_peer_is_farther(reg: SkillRegistry) -> None:
    peer = Entity(id="uav1", kind="uav", pos=(-20.0, 0.0, -5.0))
    assert await pick(request(reg, L_NEAR, L_FAR, peer)) == "cover_landmark(target_id=L0)"


async def test_an_unseen_peers_announced_position_counts(reg: SkillRegistry) -> None:
    """A peer outside sensing range that announced its intent (and position) still claims."""
    msg = intent_from("uav2", (11.0, 0.0, -5.0))
    assert await pick(request(reg, L_NEAR, L_FAR, messages=(msg,))) == (
        "cover_landmark(target_id=L1)"
    )


async def test_non_intent_messages_do_not_claim(reg: SkillRegistry) -> None:
    status = InboxMessage(
        h=Header(sender="uav2", epoch=1, seq=1, stamp=0.0),
        to="uav0",
        round=2,
        kind="status",
        sender_pos=(11.0, 0.0, -5.0),
    )
    assert await pick(request(reg, L_NEAR, L_FAR, messages=(status,))) == (
        "cover_landmark(target_id=L0)"
    )


async def test_stays_on_the_landmark_it_covers(reg: SkillRegistry) -> None:
    on_top = request(reg, L_NEAR, L_FAR, pos=(10.0, 0.0, -5.0))
    assert await pick(on_top) == "cover_landmark(target_id=L0)"


async def test_explores_when_nothing_is_visible(reg: SkillRegistry) -> None:
    assert await pick(request(reg)) == "explore_local()"


async def test_returns_in_bounds_near_the_edge(reg: SkillRegistry) -> None:
    assert await pick(request(reg, pos=(66.0, -10.0, -5.0))) == "return_in_bounds()"


async def test_is_deterministic_and_temperature_keeps_the_order(reg: SkillRegistry) -> None:
    req = request(reg, L_NEAR, L_FAR, Entity(id="uav1", kind="uav", pos=(0.0, 25.0, -5.0)))
    a = await ReferenceScorer().score(req)
    b = await ReferenceScorer().score(req)
    assert a == b
    hot = await ReferenceScorer(temperature=10.0).score(req)
    assert_distribution(hot, req)
    assert sorted(a.logprobs, key=a.logprobs.__getitem__) == sorted(
        hot.logprobs, key=hot.logprobs.__getitem__
    )
    assert max(hot.logprobs.values()) < max(a.logprobs.values())  # flatter
