"""``bench.report``: token ratios and the JSON summary computed from the cells' figures."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from aeroweaver_lab.bench.report import aggregate, summary, token_ratios

from .test_runner import cell


def test_token_ratios_per_task_from_mean_tokens() -> None:
    cells = [
        cell("coverage", "aeroweaver", 1, [-10.0], 100),
        cell("coverage", "aeroweaver", 2, [-14.0], 300),  # mean 200
        cell("coverage", "hmas2", 1, [-20.0], 1000),
        cell("coverage", "centralized", 1, [-20.0], 400),
        cell("coverage", "centralized", 2, [-20.0], 400),
        cell("line_formation", "aeroweaver", 1, [-1.0], 50),
        cell("line_formation", "centralized", 1, [-1.0], 0),  # spent nothing: no ratio
        cell("goal_concealment", "hmas2", 1, [0.0], 10),  # no AeroWeaver cell: no ratio
    ]
    ratios = token_ratios(aggregate(cells), ["coverage", "line_formation", "goal_concealment"])
    assert ratios["coverage"] == {"hmas2": pytest.approx(0.2), "centralized": pytest.approx(0.5)}
    assert ratios["line_formation"] == {"hmas2": None, "centralized": None}
    assert ratios["goal_concealment"] == {"hmas2": None, "centralized": None}


def test_summary_per_task_pooled_per_condition_and_ratios() -> None:
    cells = [
        cell("coverage", "aeroweaver", 1, [-10.0], 100),
        cell("line_formation", "aeroweaver", 1, [-14.0], 300),
        cell("coverage", "hmas2", 1, [-20.0], 1000),
    ]
    s = summary(aggregate(cells), ["coverage", "line_formation"], ["aeroweaver", "hmas2"])
    assert s["cells_finished"] == 3
    cov = s["by_task"]["coverage"]["aeroweaver"]
    assert cov["return_mean"] == -10.0
    assert cov["return_sd"] is None
    assert cov["tokens_per_episode"] == 100.0
    assert cov["uncached_prompt_per_call"] == 25.0  # 100 prompt tokens, none cached, 4 calls
    assert cov["uncached_prompt_per_decision"] == 25.0
    assert cov["holds_per_episode"] == {"chosen": 1.0}
    pooled = s["by_condition"]["aeroweaver"]
    assert pooled["episodes"] == 2
    assert pooled["return_mean"] == -12.0
    assert pooled["tokens_per_episode"] == 200.0
    assert pooled["decisions"] == 8
    assert pooled["latency_p50_s"] == 0.3  # eight latencies 0.1..0.4, nearest rank
    assert pooled["holds_per_episode"] == {"chosen": 1.0}
    assert "line_formation" not in s["by_task"] or "hmas2" not in s["by_task"]["line_formation"]
    assert s["token_ratios"]["coverage"] == {
        "aeroweaver/hmas2": 0.1,
        "aeroweaver/centralized": None,
    }
    assert s["token_ratios"]["line_formation"]["aeroweaver/hmas2"] is None


def central_round(
    rnd: int, proposal: dict[str, str], final: dict[str, str], agree: list[bool | None]
) -> dict[str, Any]:
    stages = ["plan", "revise"] if False in agree else ["plan"]  # the revision on disagreement
    return {
        "type": "round",
        "episode": 0,
        "round": rnd,
        "decisions": {},
        "central": {
            "calls": [{"stage": s} for s in stages],
            "proposal": proposal,
            "final": final,
            "reviews": {f"uav{i}": {"agree": a, "suggest": "A"} for i, a in enumerate(agree)},
        },
    }


def test_hmas2_reviews_and_revisions_are_counted_and_tabled() -> None:
    """How often the UAVs agreed with the central plan and how often the revision changed
    it: 0 revisions means HMAS-2 chose exactly as its plan (Centralized's kind of call)."""
    from aeroweaver_lab.bench.episodes import episode_metrics
    from aeroweaver_lab.bench.report import markdown

    lines = [
        # a review without a usable yes/no is silence: it buys no revision
        central_round(0, {"uav0": "A", "uav1": "B"}, {"uav0": "A", "uav1": "B"}, [True, None]),
        central_round(1, {"uav0": "A", "uav1": "B"}, {"uav0": "C", "uav1": "B"}, [False, True]),
        central_round(2, {"uav0": "A", "uav1": "A"}, {"uav0": "A", "uav1": "A"}, [False, False]),
        {"type": "round", "episode": 0, "round": 3, "decisions": {}, "central": {"calls": []}},
        {"type": "episode_end", "episode": 0, "team_return": -1.0, "reason": "horizon"},
    ]
    (ep,) = episode_metrics(lines)
    assert ep["central_reviews"] == {"asked": 6, "agreed": 2, "disagreed": 3, "failed": 0}
    assert ep["central_revised_rounds"] == 1  # round 1 only; round 3 had no reviews
    assert ep["central_revision_calls"] == 2  # rounds 1 and 2 had a disagreeing review
    assert ep["central_rounds"] == 4
    data = cell("coverage", "hmas2", 1, [-1.0], 10)
    data["episodes"][0].update(
        central_reviews=ep["central_reviews"],
        central_revised_rounds=ep["central_revised_rounds"],
        central_revision_calls=ep["central_revision_calls"],
        central_rounds=ep["central_rounds"],
    )
    table = markdown(aggregate([data]), ["coverage"], ["hmas2"])
    assert "| coverage | 1 | 2 / 3 / 1 of 6 | 2 of 4 | 1 of 4 | – |" in table
    # Centralized in the same world: equal returns on seed 1, none on seed 2
    twins = [cell("coverage", "centralized", 1, [-1.0], 10)]
    twins += [
        cell("coverage", "centralized", 2, [-3.0], 10),
        cell("coverage", "hmas2", 2, [-2.0], 10),
    ]
    table = markdown(aggregate([data, *twins]), ["coverage"], ["centralized", "hmas2"])
    assert "| 1 of 2 episodes |" in table
    del data["episodes"][0]["central_revision_calls"]  # a cell recorded before the count
    table = markdown(aggregate([data]), ["coverage"], ["hmas2"])
    assert "| coverage | 1 | 2 / 3 / 1 of 6 | – | 1 of 4 |" in table


def test_an_hmas2_cell_written_before_the_disagreement_count_is_read_from_its_trace(
    tmp_path: Path,
) -> None:
    """The archive's HMAS-2 cells predate ``disagreed``; the report recomputes their episodes
    from the trace instead of reading a missing count as 0."""
    import gzip

    from aeroweaver_lab.bench.report import load_cells

    lines = [
        central_round(0, {"uav0": "A"}, {"uav0": "A"}, [False]),
        {"type": "episode_end", "episode": 0, "team_return": -1.0, "reason": "horizon"},
    ]
    cell_dir = tmp_path / "runs" / "coverage" / "hmas2"
    cell_dir.mkdir(parents=True)
    with gzip.open(cell_dir / "seed1.trace.jsonl.gz", "wt", encoding="utf-8") as f:
        f.writelines(json.dumps(line) + "\n" for line in lines)
    data = cell("coverage", "hmas2", 1, [-1.0], 10)
    data["bench"].update(complete=True, trace="runs/coverage/hmas2/seed1.trace.jsonl.gz")
    data["episodes"][0]["central_reviews"] = {"asked": 1, "agreed": 0, "failed": 0}
    (cell_dir / "seed1.json").write_text(json.dumps(data))
    (loaded,) = load_cells(tmp_path)
    assert loaded["episodes"][0]["central_reviews"]["disagreed"] == 1


def test_paired_tests_position_bias_and_setup_tokens_in_the_table() -> None:
    from aeroweaver_lab.bench.report import markdown, paired_tests

    cells = []
    for seed in range(1, 11):
        a = cell("coverage", "aeroweaver", seed, [float(seed)], 100)
        a["bench"]["setup_tokens"] = 2500  # one Commander activation per run
        for e in a["episodes"]:
            e["picks"], e["first_label_picks"] = 4, 3
        cells.append(a)
        # Centralized: 1 lower on every seed; beta0 identical to AeroWeaver
        cells.append(cell("coverage", "centralized", seed, [seed - 1.0], 400))
        b = cell("coverage", "beta0", seed, [float(seed)], 100)
        b["bench"]["setup_tokens"] = 2500
        cells.append(b)
    stats = aggregate(cells)
    tests = paired_tests(stats, ["coverage"], ["aeroweaver", "centralized", "beta0"])
    cen = tests[("coverage", "centralized")]
    assert (cen["pairs"], cen["nonzero"], cen["mean_diff"]) == (10, 10, -1.0)
    assert cen["p"] == pytest.approx(2 / 1024)
    assert cen["p_holm"] == pytest.approx(2 / 1024)  # Centralized's family: one task
    assert tests[("coverage", "beta0")]["p"] is None  # nothing differs: nothing to test
    pooled = tests[("*", "centralized")]  # all tasks, each difference / K_t
    assert pooled["mean_diff"] == pytest.approx(-1 / 17.077)
    assert pooled["p_holm"] == pytest.approx(2 / 1024)  # beta0 has no p: a family of one
    s = stats[("coverage", "aeroweaver")]
    assert s.tokens == [2600] * 10
    assert s.setup == [2500] * 10
    assert s.per_round == [1300.0] * 10
    assert s.position_bias == 0.75
    md = markdown(stats, ["coverage"], ["aeroweaver", "centralized", "beta0"])
    assert "n = 10" in md
    assert "Model: m" in md
    assert "Δ -1.00, p 0.002 (Holm 0.002), 10 of 10 pairs differ" in md
    assert "Δ 0 on all 10 pairs" in md
    assert "| all tasks, Δ / K_t (Holm over conditions) | Δ -0.06, p 0.002" in md
    assert "| coverage | 75 % of 40 |" in md
    assert "| coverage | 2,600 | 400 | 2,600 |" in md  # tokens per episode, setup included
    assert "| coverage | 0.26 | – |" not in md
    assert "AeroWeaver / Centralized" in md
    assert "| coverage | – | 6.50 |" in md  # 2,600 / 400, setup counted in AeroWeaver's


def test_holm_families_are_per_condition_so_n10_can_reject() -> None:
    """Nine tasks, AeroWeaver higher by 1 on every seed of every task under one ablation:
    each raw p is 2/1024, Holm over the condition's nine tasks gives 9 x 2/1024 < 0.05 (over
    the whole table it could not: 54 x 2/1024 > 0.05)."""
    from aeroweaver_lab.bench.report import PAPER_K, paired_tests

    cells = []
    for t in PAPER_K:
        for seed in range(1, 11):
            cells.append(cell(t, "aeroweaver", seed, [float(seed)], 100))
            cells.append(cell(t, "no_coordination", seed, [seed - 1.0], 100))
    tests = paired_tests(aggregate(cells), list(PAPER_K), ["aeroweaver", "no_coordination"])
    for t in PAPER_K:
        assert tests[(t, "no_coordination")]["p"] == pytest.approx(2 / 1024)
        assert tests[(t, "no_coordination")]["p_holm"] == pytest.approx(9 * 2 / 1024)
    assert tests[("*", "no_coordination")]["pairs"] == 90
    assert tests[("*", "no_coordination")]["p"] < 1e-20
