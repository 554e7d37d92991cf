"""The adaptation figures computed from traces: gaps, pushes, corrected picks and the age
bias of in-flight returns."""

from __future__ import annotations

from typing import Any

import pytest

from aeroweaver_edge.bench.adaptation_why import age_bias, decision_figures

OPTS = ["A. cover_landmark(target_id=L0)", "B. explore_local()", "C. hold_position()"]


def row(
    rnd: int, decisions: dict[str, dict[str, Any]], rewards: dict[str, float]
) -> dict[str, Any]:
    return {"type": "round", "episode": 0, "round": rnd, "decisions": decisions, "rewards": rewards}


def test_decision_figures() -> None:
    trace = [
        row(
            0,
            {
                "uav0": {
                    "options": OPTS,
                    "base": {"A": -0.5, "B": -1.5, "C": -2.0},
                    "advantage": {},
                    "chosen": "A",
                    "skill": "hold_position",
                    "hold_cause": None,
                }
            },
            {"uav0": -1.0},
        ),
        row(
            1,
            {
                "uav0": {
                    "options": OPTS,
                    "base": {"A": -0.5, "B": -1.0, "C": -1.1},
                    "advantage": {"A": -1.0, "C": 2.0},
                    "chosen": "C",
                    "corrected": True,
                    "skill": "hold_position",
                    "hold_cause": "chosen",
                }
            },
            {"uav0": -0.5},
        ),
    ]
    f = decision_figures(trace, beta=0.8)
    assert f["decisions"] == 2
    assert f["scored"] == 2
    assert f["base_gap_median"] == pytest.approx(0.75)  # gaps 1.0 and 0.5
    assert f["correction_push_median"] == pytest.approx(0.8 * 3.0 / 2)  # pushes 0 and 2.4
    assert f["corrected"] == 1
    assert f["corrected_to_hold"] == 1
    assert f["corrected_to_last_skill"] == 1  # round 0's executed skill was hold_position
    assert f["advantage_last_skill_mean"] == pytest.approx(2.0)
    assert f["advantage_other_skills_mean"] == pytest.approx(-0.5)
    assert f["holds_by_cause"]["chosen"] == 1


def test_age_bias_of_in_flight_returns() -> None:
    trace = [row(r, {"uav0": {}}, {"uav0": -1.0}) for r in range(4)]
    out = age_bias([trace], gamma=0.5)
    assert out["in_flight_by_age"] == {1: -1.0, 2: -1.5, 4: -1.875}
    # finalised returns: rounds 0..3 collect 4, 3, 2, 1 rewards
    assert out["finalised_mean"] == pytest.approx((-1.875 - 1.75 - 1.5 - 1.0) / 4, abs=1e-3)
