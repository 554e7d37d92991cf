"""The baselines' prompts, schemas and answer checks: a letter counts only if it is one of
that UAV's own options; anything else holds that UAV alone."""

from __future__ import annotations

from aeroweaver_edge.contracts.wire import CentralAsk, Header
from aeroweaver_lab.baselines.protocol import (
    Mission,
    Review,
    check_plan,
    check_review,
    labels_of,
    option_text,
    plan_messages,
    review_schema,
    revision_messages,
    team_schema,
)

H = Header(sender="uav0", epoch=1, seq=1, stamp=0.0)


def ask(uav: str, rnd: int, observation: str, options: list[str]) -> CentralAsk:
    return CentralAsk(
        h=H,
        uav=uav,
        episode=0,
        round=rnd,
        role="searcher",
        local_goal="cover one landmark",
        observation=observation,
        messages=[f"{uav} intent r{rnd}: skill=x"],
        options=options,
    )


OPTS = ["A. cover_landmark(target_id=L0)", "B. explore_local()", "C. hold_position()"]
LABELS = {"uav0": ["A", "B", "C"], "uav1": ["A", "B"]}


def test_labels_and_option_text() -> None:
    assert labels_of(OPTS) == ["A", "B", "C"]
    assert labels_of(["garbage", "D. x()"]) == ["D"]
    assert option_text(OPTS, "B") == "B. explore_local()"
    assert option_text(OPTS, "Z") == "(none)"
    assert option_text(OPTS, None) == "(none)"


def test_a_valid_plan_gives_every_uav_its_letter() -> None:
    check = check_plan({"uav0": "C", "uav1": " b. "}, LABELS)
    assert check.labels == {"uav0": "C", "uav1": "B"}
    assert check.invalid == {}


def test_an_invalid_letter_holds_only_that_uav() -> None:
    check = check_plan({"uav0": "C", "uav1": "C", "uav9": "A"}, LABELS)  # uav1 has no C
    assert check.labels == {"uav0": "C", "uav1": None}
    assert set(check.invalid) == {"uav1"}


def test_missing_or_malformed_entries_hold_those_uavs() -> None:
    check = check_plan({"uav0": 1}, LABELS)
    assert check.labels == {"uav0": None, "uav1": None}
    assert set(check.invalid) == {"uav0", "uav1"}
    nothing = check_plan(None, LABELS)
    assert nothing.labels == {"uav0": None, "uav1": None}
    assert all("no JSON" in why for why in nothing.invalid.values())


def test_review_checks() -> None:
    assert check_review({"agree": True, "choice": "A"}, ["A", "B"]) == Review(True, "A")
    assert check_review({"agree": False, "choice": "z"}, ["A", "B"]) == Review(False, None)
    assert check_review({"agree": "yes", "choice": "A"}, ["A"]) == Review(None, None)
    assert check_review(None, ["A"]) == Review(None, None)


def test_schemas_allow_only_each_uavs_letters() -> None:
    s = team_schema(LABELS)
    assert s["required"] == ["uav0", "uav1"]
    assert s["properties"]["uav1"] == {"type": "string", "enum": ["A", "B"]}
    assert s["additionalProperties"] is False
    r = review_schema(["A", "B"])
    assert r["required"] == ["agree", "choice"]
    assert r["properties"]["choice"]["enum"] == ["A", "B"]


def test_plan_prompt_keeps_the_mission_part_stable_and_carries_each_uavs_view() -> None:
    mission = Mission("Cover the landmarks.", ["stay in the arena"], ["cover_landmark: doc"])
    r1 = plan_messages(mission, 0, 1, [ask("uav0", 1, "landmark L0: 10 m N", OPTS)])
    r2 = plan_messages(mission, 0, 2, [ask("uav0", 2, "landmark L0: 5 m N", OPTS[:2])])
    assert r1[0] == r2[0]  # the system part is identical across rounds (prompt cache)
    assert "cover_landmark: doc" in r1[0]["content"]
    assert "uav0: role searcher; goal: cover one landmark" in r1[0]["content"]
    user = r1[1]["content"]
    for piece in (
        "## Round 1",
        "### uav0 (searcher)",
        "landmark L0: 10 m N",
        *OPTS,
        "uav0 intent r1: skill=x",
    ):
        assert piece in user
    assert "C. hold_position()" not in r2[1]["content"]


def test_revision_continues_the_plan_conversation_with_the_reviews() -> None:
    asks = [ask("uav0", 3, "o", OPTS), ask("uav1", 3, "o", OPTS[:2])]
    plan = plan_messages(Mission("m"), 0, 3, asks)
    msgs = revision_messages(
        plan,
        '{"uav0": "A", "uav1": "A"}',
        asks,
        {"uav0": "A", "uav1": "A"},
        {"uav0": Review(True, "A"), "uav1": Review(False, "B")},
    )
    assert msgs[:2] == plan  # same prefix: the revision reuses the plan's cache
    assert msgs[2] == {"role": "assistant", "content": '{"uav0": "A", "uav1": "A"}'}
    text = msgs[3]["content"]
    assert "uav0 agrees with A. cover_landmark(target_id=L0)" in text
    assert (
        "uav1 disagrees with A. cover_landmark(target_id=L0); it would take B. explore_local()"
        in text
    )
