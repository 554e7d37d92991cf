from __future__ import annotations

from typing import Any

import pytest
from pydantic import ValidationError

from aeroweaver_edge.tasks import specs
from commander.task_record import TASK_TYPES, TaskRecord, validation_summary

ROSTER = ["uav0", "uav1", "uav2", "uav3"]


def _validate(**data: Any) -> TaskRecord:
    base: dict[str, Any] = {"task": "coverage", "uavs": ["uav0", "uav1"]}
    return TaskRecord.model_validate({**base, **data}, context={"roster": ROSTER})


def _error(**data: Any) -> str:
    with pytest.raises(ValidationError) as e:
        _validate(**data)
    return validation_summary(e.value)


def test_nine_tasks_with_roles() -> None:
    assert len(TASK_TYPES) == 9
    assert set(specs()) == set(TASK_TYPES)
    assert specs()["world_communication"].role_names == ("leader", "pursuer")
    assert specs()["pursuit_evasion"].scripted_names == ("evader",)


def test_valid_record_with_region() -> None:
    r = _validate(
        region={"kind": "circle", "north_m": 10, "east_m": -20, "radius_m": 30},
        constraints=["avoid collisions"],
        role_counts={"searcher": 2},
        text="cover",
    )
    assert r.region is not None
    assert r.region.describe().startswith("within 30 m")
    assert r.uavs == ("uav0", "uav1")


@pytest.mark.parametrize(
    ("data", "field", "words"),
    [
        ({"task": "search_and_rescue"}, "task", "unknown task type"),
        ({"uavs": ["uav0", "uav9"]}, "uavs", "uav9 not in the live roster"),
        ({"uavs": ["uav0", "uav0"]}, "uavs", "duplicate"),
        ({"uavs": []}, "uavs", "at least 1"),
        ({"role_counts": {"chaser": 2}}, "role_counts", "not a role of coverage"),
        ({"role_counts": {"searcher": 3}}, "role_counts", "need 3 UAVs but 2 take part"),
        (
            {"region": {"kind": "circle", "north_m": 100, "east_m": 0, "radius_m": 5}},
            "region.north_m",
            "less than or equal to 70",
        ),
        (
            {
                "region": {
                    "kind": "box",
                    "north_min_m": 10,
                    "north_max_m": 0,
                    "east_min_m": 0,
                    "east_max_m": 5,
                }
            },
            "region",
            "north_min_m < north_max_m",
        ),
        ({"colour": "red"}, "colour", "unknown field"),
    ],
)
def test_errors_name_the_field(data: dict[str, Any], field: str, words: str) -> None:
    msg = _error(**data)
    assert f"field '{field}'" in msg
    assert words in msg


def test_task_size_bounds() -> None:
    msg = _error(task="private_communication", uavs=["uav0", "uav1", "uav2"])
    assert "field 'uavs'" in msg
    assert "exactly 2 UAVs (sender, receiver)" in msg
    msg = _error(task="guided_navigation", uavs=["uav0"])
    assert "2 to 50 UAVs" in msg


def test_scripted_roles_may_be_counted_but_do_not_take_uavs() -> None:
    r = TaskRecord.model_validate(
        {"task": "pursuit_evasion", "uavs": ROSTER[:3], "role_counts": {"pursuer": 3, "evader": 1}},
        context={"roster": ROSTER},
    )
    assert r.role_counts == {"pursuer": 3, "evader": 1}


def test_llm_schema_omits_text() -> None:
    schema = TaskRecord.llm_schema()
    assert "text" not in schema["properties"]
    assert {"task", "uavs", "region", "role_counts", "constraints"} <= set(schema["properties"])
