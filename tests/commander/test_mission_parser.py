from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import pytest

from commander.mission_parser import (
    MissionParseError,
    first_json_object,
    parse_fallback,
    parse_mission,
)

ROSTER3 = ["uav0", "uav1", "uav2"]
ROSTER10 = [f"uav{i}" for i in range(10)]


# --------------------------------------------------------------------------- fallback rules


@pytest.mark.parametrize(
    ("text", "task"),
    [
        ("Cover the landmarks.", "coverage"),
        ("Spread out over the landmarks and hold there.", "coverage"),
        ("Chase the intruder.", "pursuit_evasion"),
        ("Pursue the intruder until it is caught.", "pursuit_evasion"),
        ("Catch the intruder drone.", "pursuit_evasion"),
        ("Guide the listener to the goal landmark.", "guided_navigation"),
        ("The speaker tells the listener where to go.", "guided_navigation"),
        ("Send a secret message to the receiver.", "private_communication"),
        ("Send an encrypted message past the eavesdropper.", "private_communication"),
        ("Form a circle around the centre marker.", "circular_formation"),
        ("Form a ring.", "circular_formation"),
        ("Line up between the two endpoints.", "line_formation"),
        ("Form a line.", "line_formation"),
        ("The leader tells the pursuers where the foragers are.", "world_communication"),
        ("Deliver the treasure to the deposits.", "collection_delivery"),
        ("Collect treasure.", "collection_delivery"),
        ("Conceal the goal from the adversary.", "goal_concealment"),
        ("Hide the goal; send one drone to a decoy.", "goal_concealment"),
    ],
)
def test_fallback_task_types(text: str, task: str) -> None:
    r = parse_fallback(text, ROSTER10)
    assert r.task == task
    assert r.text == text
    assert set(r.uavs) <= set(ROSTER10)


@pytest.mark.parametrize(
    ("text", "n"),
    [
        ("Cover the three landmarks with three drones.", 3),
        ("Cover the landmarks with 5 UAVs.", 5),
        ("Form a circle with seven drones.", 7),
        ("Use four of our drones to cover the landmarks.", 4),
        ("Cover the landmarks with one drone.", 1),
        ("Cover the landmarks, one drone per landmark. No two drones on one landmark.", 3),
        ("Form a line.", 5),  # no number: the task's default team
    ],
)
def test_fallback_counts(text: str, n: int) -> None:
    r = parse_fallback(text, ROSTER10)
    assert len(r.uavs) == n
    assert r.uavs == tuple(ROSTER10[:n])


def test_role_counts_and_implied_total() -> None:
    r = parse_fallback("Three pursuers must chase down the intruder.", ROSTER10)
    assert r.role_counts == {"pursuer": 3}
    assert len(r.uavs) == 3
    r = parse_fallback("The leader tells four pursuers where the foragers are.", ROSTER10)
    assert r.role_counts == {"pursuer": 4}
    assert len(r.uavs) == 5


def test_named_uavs() -> None:
    r = parse_fallback("uav1 and uav3 cover the landmarks.", ROSTER10)
    assert r.uavs == ("uav1", "uav3")


@pytest.mark.parametrize(
    ("text", "region"),
    [
        (
            "Cover the landmarks in the north-east quadrant.",
            {"kind": "box", "north_min_m": 0, "north_max_m": 70, "east_min_m": 0, "east_max_m": 70},
        ),
        (
            "Cover the landmarks in the south west corner.",
            {
                "kind": "box",
                "north_min_m": -70,
                "north_max_m": 0,
                "east_min_m": -70,
                "east_max_m": 0,
            },
        ),
        (
            "Cover the landmarks within 30 m of (10, -20).",
            {"kind": "circle", "north_m": 10, "east_m": -20, "radius_m": 30},
        ),
        (
            "Form a circle within 25 metres of the centre.",
            {"kind": "circle", "north_m": 0, "east_m": 0, "radius_m": 25},
        ),
        (
            "Cover the landmarks in the northern half.",
            {
                "kind": "box",
                "north_min_m": 0,
                "north_max_m": 70,
                "east_min_m": -70,
                "east_max_m": 70,
            },
        ),
        (
            "Cover the landmarks in north -20 to 30, east 0 to 40.",
            {
                "kind": "box",
                "north_min_m": -20,
                "north_max_m": 30,
                "east_min_m": 0,
                "east_max_m": 40,
            },
        ),
    ],
)
def test_fallback_regions(text: str, region: dict[str, Any]) -> None:
    r = parse_fallback(text, ROSTER10)
    assert r.region is not None
    assert r.region.model_dump() == region


def test_region_outside_arena_is_refused_naming_the_field() -> None:
    with pytest.raises(MissionParseError, match=r"field 'region.north_m'"):
        parse_fallback("Cover the landmarks within 30 m of (100, 0).", ROSTER10)


def test_constraints_are_kept() -> None:
    r = parse_fallback(
        "Cover the three landmarks with three drones. Avoid collisions between drones.", ROSTER10
    )
    assert r.constraints == ("Avoid collisions between drones",)


@pytest.mark.parametrize(
    ("text", "roster", "message"),
    [
        (
            "Make me a sandwich.",
            ROSTER3,
            "no task type recognised in 'Make me a sandwich.'; known tasks: coverage, "
            "pursuit_evasion",
        ),
        (
            "Cover the landmarks with 5 drones.",
            ROSTER3,
            "asked for 5 drones but only 3 are up: uav0, uav1, uav2",
        ),
        ("Cover the landmarks.", [], "no UAVs are up"),
        (
            "uav7 covers the landmarks.",
            ROSTER3,
            "the mission names uav7 but only these are up: uav0, uav1, uav2",
        ),
        ("Form a circle.", ["uav0"], "circular_formation needs 2 to 50 UAVs"),
        (
            "Form a ring or a row.",
            ROSTER3,
            "it reads as circular_formation and line_formation equally",
        ),
        ("   ", ROSTER3, "empty"),
    ],
)
def test_unparsable_missions_say_what_is_missing(
    text: str, roster: list[str], message: str
) -> None:
    with pytest.raises(MissionParseError) as e:
        parse_fallback(text, roster)
    assert message in str(e.value)


def test_first_json_object() -> None:
    assert first_json_object('Sure! ```json\n{"a": {"b": 1}}\n``` done') == {"a": {"b": 1}}
    assert first_json_object('{not json} then {"x": 2}') == {"x": 2}
    assert first_json_object("[1, 2]") is None
    assert first_json_object("nothing") is None


# --------------------------------------------------------------------------- LLM path

LLM = Callable[..., Any]
COVER = "Cover the three landmarks with three drones. Avoid collisions."


def _record(**over: Any) -> str:
    data = {
        "task": "coverage",
        "uavs": ["uav0", "uav1", "uav2"],
        "role_counts": {},
        "region": None,
        "constraints": ["avoid collisions"],
    }
    data.update(over)
    return json.dumps(data)


async def test_llm_happy_path(llm: LLM) -> None:
    fp, client = await llm(["Here is the record:\n```json\n" + _record() + "\n```"])
    out = await parse_mission(COVER, ROSTER10, client)
    assert out.source == "llm"
    assert out.record.task == "coverage"
    assert out.record.uavs == ("uav0", "uav1", "uav2")
    assert out.record.text == COVER  # the original, not the model's copy
    assert out.tokens > 0
    assert out.tokens == client.ledger.total.total_tokens
    body = fp.chat_bodies()[0]
    assert body["response_format"]["type"] == "json_schema"
    assert body["response_format"]["json_schema"]["schema"]["properties"]["task"]
    assert "uav0, uav1" in body["messages"][0]["content"]  # the roster is in the prompt


@pytest.mark.parametrize(
    ("answer", "reason"),
    [
        ("I am sorry, I cannot help with drones.", "no JSON object in the answer"),
        ('{"task": "coverage", "uavs": ["uav0"', "no JSON object in the answer"),
        (_record(task="search_and_rescue"), "field 'task'"),
        (_record(uavs=["uav0", "uav1", "uav42"]), "uav42 not in the live roster"),
        (_record(colour="red"), "field 'colour': unknown field"),
        (_record(task="pursuit_evasion"), "the text clearly names coverage"),
        (_record(uavs=["uav0", "uav1"]), "LLM chose 2 UAVs but the text asks for 3"),
        (500, "LLMHTTPError: HTTP 500"),
    ],
)
async def test_llm_failures_fall_back_with_reason(llm: LLM, answer: str | int, reason: str) -> None:
    _, client = await llm([answer])
    out = await parse_mission(COVER, ROSTER10, client)
    assert out.source == "fallback"
    assert out.record.task == "coverage"
    assert len(out.record.uavs) == 3
    assert out.llm_error is not None
    assert reason in out.llm_error
    assert any(reason in n and "rule-based parser" in n for n in out.notes)
    assert out.endpoint_failed == isinstance(answer, int)
    if not isinstance(answer, int):
        assert out.tokens > 0  # tokens spent on a rejected answer still count


async def test_response_format_refused_is_retried_plain(llm: LLM) -> None:
    fp, client = await llm([400, _record()])
    out = await parse_mission(COVER, ROSTER10, client)
    assert out.source == "llm"
    first, second = fp.chat_bodies()
    assert "response_format" in first
    assert "response_format" not in second
    assert any("refused the request with response_format" in n for n in out.notes)


async def test_llm_can_understand_what_rules_cannot(llm: LLM) -> None:
    # The task descriptions now carry "every marker ... each" to coverage on their own:
    assert parse_fallback("Keep an eye on every marker at once, one bird each.", ROSTER10).task == (
        "coverage"
    )
    text = "Each bird should babysit one of the pins."  # too little in common with any task
    with pytest.raises(MissionParseError):
        parse_fallback(text, ROSTER10)
    _, client = await llm([_record()])
    out = await parse_mission(text, ROSTER10, client)
    assert out.source == "llm"
    assert out.record.task == "coverage"


async def test_neither_understands(llm: LLM) -> None:
    _, client = await llm(["no idea"])
    with pytest.raises(MissionParseError) as e:
        await parse_mission("Make me a sandwich.", ROSTER10, client)
    assert "no task type recognised" in str(e.value)
    assert "the LLM did not help either: no JSON object" in str(e.value)


async def test_no_client_uses_rules() -> None:
    out = await parse_mission(COVER, ROSTER10, None)
    assert out.source == "fallback"
    assert out.tokens == 0
