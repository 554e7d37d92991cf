"""The adaptation figures computed from traces: gaps, pushes, corrected picks and the age
bias of in-flight returns."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from aeroweaver_lab.bench.adaptation_why import age_bias, analyse_bench, decision_figures, main

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
    # the UAV held in round 0 (its skill was hold_position): round 1's pick is a repeat
    assert (f["hold_entries"], f["hold_repeats"]) == (0, 1)
    assert f["advantage_hold_at_repeat_mean"] == pytest.approx(2.0)


def test_hold_entry_counted_with_unseen_hold_and_the_winner_advantage() -> None:
    pick = {"options": OPTS, "base": {"A": -0.5, "B": -1.0, "C": -1.1},
            "advantage": {"A": -3.0, "B": 1.0}, "chosen": "C", "corrected": True,
            "skill": "hold_position", "hold_cause": "chosen"}  # fmt: skip
    first = {**pick, "corrected": False, "chosen": "A", "skill": "cover_landmark"}
    trace = [row(0, {"uav0": first}, {}), row(1, {"uav0": pick}, {}), row(2, {"uav0": pick}, {})]
    f = decision_figures(trace, beta=0.8)
    assert (f["hold_entries"], f["hold_entries_unseen"], f["hold_repeats"]) == (1, 1, 1)
    assert f["advantage_winner_at_hold_entry_mean"] == pytest.approx(-3.0)
    assert f["advantage_hold_at_repeat_mean"] == pytest.approx(0.0)


def test_age_bias_of_in_flight_returns() -> None:
    trace = [row(r, {"uav0": {}}, {"uav0": -1.0}) for r in range(4)]
    out = age_bias([trace], gamma=0.5)
    assert out["in_flight_by_age"] == {1: -1.0, 2: -1.5, 4: -1.875}
    # finalised returns: rounds 0..3 collect 4, 3, 2, 1 rewards
    assert out["finalised_mean"] == pytest.approx((-1.875 - 1.75 - 1.5 - 1.0) / 4, abs=1e-3)


def _bench_cell(out: Path, cond: str, beta: float, trace: list[dict[str, Any]], done: bool) -> None:
    stem = out / "runs" / "coverage" / cond / "seed1"
    stem.parent.mkdir(parents=True, exist_ok=True)
    header = {"type": "run", "beta": beta}
    rows = [header, *trace, {"type": "episode_end", "episode": 0, "team_return": -1.5}]
    stem.with_suffix(".trace.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    cell = {
        "bench": {"task": "coverage", "seed": 1, "complete": done,
                  "trace": f"runs/coverage/{cond}/seed1.trace.jsonl"},
        "episodes": [{"team_return": -1.5}],
        "summary": {"selector": "llm:m"},
    }  # fmt: skip
    stem.with_suffix(".json").write_text(json.dumps(cell))


def test_bench_cells_compared_as_beta_variants(tmp_path: Path) -> None:
    """A `bench run` directory: its AeroWeaver cell is beta=0.8, its beta0 cell beta=0, with
    beta read from the trace; other conditions and unfinished cells are left out."""
    corrected = row(
        0,
        {"uav0": {"options": OPTS, "base": {"A": -0.5, "B": -1.0, "C": -1.1},
                  "advantage": {"A": -1.0, "C": 2.0}, "chosen": "C", "corrected": True,
                  "skill": "hold_position", "hold_cause": "chosen"}},
        {"uav0": -1.0},
    )  # fmt: skip
    plain = row(0, {"uav0": {"options": OPTS, "base": {"A": -0.5, "B": -1.0}}}, {"uav0": -1.0})
    _bench_cell(tmp_path, "aeroweaver", 0.5, [corrected], True)
    _bench_cell(tmp_path, "beta0", 0.0, [plain], True)
    _bench_cell(tmp_path, "centralized", 0.0, [plain], True)
    _bench_cell(tmp_path, "no_activation", 0.8, [corrected], False)
    rows = analyse_bench(tmp_path, gamma=0.95)
    assert [(r["variant"], r["seed"], r["mean_return"]) for r in rows] == [
        ("beta=0.8", 1, -1.5),
        ("beta=0", 1, -1.5),
    ]
    full, zero = rows
    assert full["corrected"] == 1
    assert full["corrected_to_hold"] == 1
    assert full["correction_push_median"] == pytest.approx(0.5 * 3.0)  # the trace's beta
    assert full["holds_by_cause"]["chosen"] == 1
    assert zero["corrected"] == 0
    assert zero["base_gap_median"] == pytest.approx(0.5)
    assert main([str(tmp_path), "--bench"]) == 0
    why = (tmp_path / "why.md").read_text()
    assert "| coverage | beta=0.8 | 1 |" in why
    assert "| coverage | beta=0.8 | 1 | 0 | -1.00 | 0 | – |" in why  # an entry, A(hold) 2.0
