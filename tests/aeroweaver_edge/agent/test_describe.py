"""The two renderings of an observation: terse for the prompt, one entity a line for retrieval."""

from __future__ import annotations

from aeroweaver_edge.agent.describe import describe, describe_state
from aeroweaver_edge.agent.state_tokens import tokenise
from aeroweaver_edge.contracts.observation import Observation, VehicleState
from aeroweaver_edge.contracts.wire import Entity


def observation(entities: tuple[Entity, ...]) -> Observation:
    return Observation(
        uav="uav0",
        episode=0,
        round=3,
        own=VehicleState(pos=(-11.0, 14.0, -5.0), vel=(3.0, 4.0, 0.0)),
        entities=entities,
    )


ENTITIES = (
    Entity(kind="uav", id="uav2", pos=(0.0, 14.0, -5.0), role="searcher"),
    Entity(kind="landmark", id="L1", pos=(-11.0, -16.0, 0.0)),
    Entity(kind="landmark", id="L0", pos=(19.0, 44.0, 0.0)),
    Entity(kind="food", id="F1", pos=(-31.0, 14.0, 0.0), role="red"),
    Entity(kind="uav", id="uav1", pos=(-11.0, 24.0, -5.0), role="searcher"),
)


def test_the_prompt_reads_one_line_per_kind_of_entity_with_id_distance_and_bearing() -> None:
    assert describe(observation(ENTITIES)).splitlines() == [
        "you -10,15",
        "food (red): F1 20 S",
        "landmark: L0 40 NE, L1 30 W",
        "searcher: uav1 10 E, uav2 10 N",
    ]
    assert describe(observation(())) == "you -10,15\nnothing in range"


def test_the_retrieval_text_keeps_one_entity_a_line_so_stored_experience_still_matches() -> None:
    text = describe_state(observation(ENTITIES))
    assert text.splitlines() == [
        "you: north -10 east 15, speed 5 m/s",
        "food (red) F1: 20 m S",
        "landmark L0: 40 m NE",
        "landmark L1: 30 m W",
        "searcher uav1: 10 m E",
        "searcher uav2: 10 m N",
    ]
    assert {"uav1~10", "l0~30", "l1~30"} <= tokenise(text)  # id paired with its distance
