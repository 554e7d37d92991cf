"""The per-round trace explains the summary: its rewards add up to the returns, every UAV's
decision is there with its options, scores and pick, and every body (opponents too)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm


@pytest.mark.parametrize(("task", "bodies"), [("coverage", 3), ("pursuit_evasion", 4)])
async def test_trace_rounds_add_up_to_the_summary(tmp_path: Path, task: str, bodies: int) -> None:
    path = tmp_path / "run" / "trace.jsonl"
    summary = await run_swarm(
        SwarmOptions(task=task, selector="scripted", max_rounds=5, seed=2, trace_path=path)
    )
    data = summary.as_dict()
    assert data["trace"] == str(path)
    rows = [json.loads(line) for line in path.read_text().splitlines()]
    head, *rounds, end = rows
    assert head["type"] == "run"
    assert head["task"] == task
    assert head["roles"] == data["roles"]
    assert [r["round"] for r in rounds] == list(range(data["rounds"]))
    assert end == {**end, "type": "episode_end", "rounds": data["rounds"]}
    uavs = sorted(data["agent_returns"])
    for r in rounds:
        assert len(r["bodies"]) == bodies  # ours and the world's opponents
        assert sorted(r["decisions"]) == uavs  # every UAV's report joined to its round
        for d in r["decisions"].values():
            labels = [o.split(".", 1)[0] for o in d["options"]]
            assert d["chosen"] in labels
            assert d["label"] == d["chosen"]
            assert set(d["base"]) <= set(labels)
            shown = d["options"][labels.index(d["chosen"])].split(". ", 1)[1]  # as prompted
            skill, args = shown.split("(", 1)
            assert d["invocation"].startswith(skill + "(")  # same skill, and same value:
            assert args.rstrip(")") in d["invocation"]  # cover_landmark(L0) is target_id=L0
    for u in uavs:
        total = math.fsum(r["rewards"][u] for r in rounds)
        assert total == pytest.approx(data["agent_returns"][u], abs=1e-5)
        assert end["returns"][u] == pytest.approx(data["agent_returns"][u], abs=1e-5)
