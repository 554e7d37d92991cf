"""The retrieval state text: observation + peer messages + mission context (paper §3.3)."""

from __future__ import annotations

from aeroweaver_edge.agent.state_text import MAX_MESSAGES, message_summary, state_text
from aeroweaver_edge.agent.state_tokens import jaccard, tokenise
from aeroweaver_edge.contracts.observation import MissionView, Observation, VehicleState
from aeroweaver_edge.contracts.wire import Entity, Header, InboxMessage

VIEW = MissionView(
    mission_id="m1",
    task="coverage",
    text="Cover every landmark.",
    role="searcher",
    local_goal="Reach a landmark   no other drone covers.",
    skills=("cover_landmark",),
)


def msg(sender: str, body: dict[str, str | int | float | bool], seq: int = 1) -> InboxMessage:
    return InboxMessage(
        h=Header(sender=sender, epoch=1, seq=seq, stamp=0.0),
        to="uav1",
        round=4,
        kind="intent",
        body=body,
    )


def obs(
    messages: tuple[InboxMessage, ...] = (),
    pos: tuple[float, float] = (0.0, 0.0),
    memo: dict[str, str] | None = None,
) -> Observation:
    return Observation(
        uav="uav1",
        episode=0,
        round=5,
        own=VehicleState((pos[0], pos[1], -5.0), (0.0, 0.0, 0.0)),
        entities=(Entity(kind="landmark", id="L1", pos=(20.0, 0.0, 0.0)),),
        messages=messages,
        memo=memo or {},
    )


INTENT = {"skill": "cover_landmark", "target_id": "L2", "north": 34.13935298863066, "east": 0.2}


def test_full_state_holds_progress_observation_mission_context_and_messages() -> None:
    text = state_text(obs((msg("uav2", INTENT),), memo={"goal_landmark": "L3"}), VIEW, context=True)
    assert text.splitlines() == [
        "round 5",
        "you: north 0 east 0, speed 0 m/s",
        "landmark L1: 20 m N",
        "role searcher; goal Reach a landmark no other drone covers.",
        "fact goal_landmark L3",
        "msg uav2 intent: skill cover_landmark target_id L2 at 35 m N",
    ]


def test_observation_only_state_is_progress_pose_and_entities() -> None:
    text = state_text(obs((msg("uav2", INTENT),)), VIEW, context=False)
    assert text == "round 5\nyou: north 0 east 0, speed 0 m/s\nlandmark L1: 20 m N"


def test_alike_states_share_tokens_despite_small_coordinate_differences() -> None:
    a = state_text(obs((msg("uav2", INTENT),)), VIEW, context=True)
    nudged = {**INTENT, "north": 33.2, "east": 0.9}
    b = state_text(obs((msg("uav2", nudged),), pos=(0.4, -0.3)), VIEW, context=True)
    assert a == b  # rounded to 5 m: the same text, so the same tokens
    other = state_text(obs((msg("uav2", {**INTENT, "target_id": "L3"}),)), VIEW, context=True)
    assert 0.5 < jaccard(tokenise(a), tokenise(other)) < 1.0


def test_message_order_does_not_change_the_state() -> None:
    m1, m2 = msg("uav2", INTENT), msg("uav3", {"skill": "explore_local"}, seq=2)
    assert state_text(obs((m1, m2)), VIEW, context=True) == state_text(
        obs((m2, m1)), VIEW, context=True
    )


def test_hostile_bodies_are_reduced_to_bounded_identifiers() -> None:
    evil = {"note\nrole": "x" * 500 + "<script>", "n": float("inf"), "flag": True}
    line = message_summary(msg("uav\n9", evil), (0.0, 0.0))
    assert "\n" not in line
    assert "<" not in line
    assert line == "msg uav_9 intent: flag true n nan note_role " + "x" * 24
    many = tuple(msg(f"uav{i}", {"i": i}, seq=i) for i in range(30))
    text = state_text(obs(many), VIEW, context=True)
    assert sum(line.startswith("msg ") for line in text.splitlines()) == MAX_MESSAGES
    assert len(text) < 2000
