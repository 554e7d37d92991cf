"""HMAS-2 with a failing endpoint (a real loopback HTTP server answering 503; real Zenoh):
the central plan call fails, no proposal goes out, and every UAV holds at once as
``llm_failure`` -- not after waiting out the round deadline as ``deadline`` -- so the bench
refuses the cell as unusable, as it does for Centralized on the same endpoint."""

from __future__ import annotations

import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any, Literal

import pytest

from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm
from aeroweaver_lab.baselines.wiring import CentralBaseline
from aeroweaver_lab.bench.episodes import episode_metrics, read_trace
from aeroweaver_lab.bench.runner import llm_failure_problem

ROUNDS = 2
DEADLINE_S = 60.0  # what a UAV would wait per round for a proposal that never comes


@pytest.fixture
async def failing() -> AsyncIterator[FakeProvider]:
    async with FakeProvider(Policy(status=503), n_slots=8) as fp:
        yield fp


async def run(
    fp: FakeProvider, tmp: Path, baseline: Literal["centralized", "hmas2"]
) -> tuple[dict[str, Any], float]:
    trace = tmp / f"{baseline}.jsonl"
    opts = SwarmOptions(
        task="coverage", seed=3, max_rounds=ROUNDS, trace_path=trace,
        central=CentralBaseline(baseline), activation="full", beta=0.0, deadline_s=DEADLINE_S,
        llm=LLMConfig(base_url=fp.base_url, model="fake-model", deadline_s=5, retries=0),
    )  # fmt: skip
    started = time.monotonic()
    data = (await run_swarm(opts)).as_dict()
    data["_episodes"] = episode_metrics(read_trace(trace))
    data["_trace"] = read_trace(trace)
    return data, time.monotonic() - started


@pytest.mark.parametrize("baseline", ["hmas2", "centralized"])
async def test_a_failed_central_call_holds_every_uav_at_once_as_llm_failure(
    failing: FakeProvider, tmp_path: Path, baseline: Literal["centralized", "hmas2"]
) -> None:
    data, wall = await run(failing, tmp_path, baseline)
    assert wall < DEADLINE_S / 2  # no round waited out its deadline
    rounds = [r for r in data["_trace"] if r["type"] == "round"]
    assert len(rounds) == ROUNDS
    for r in rounds:
        causes = {d["hold_cause"] for d in r["decisions"].values()}
        assert causes == {"llm_failure"}, causes
        if baseline == "hmas2":
            assert [c["stage"] for c in r["central"]["calls"]] == ["plan"]
            assert r["central"]["reviews"] == {}  # no proposal, so no review was asked for
    problem = llm_failure_problem(data["_episodes"])
    assert problem is not None
    assert "LLM call failed" in problem
    assert data["central"]["llm_calls"] >= ROUNDS  # the requests sent are counted


def test_lost_reviews_make_the_cell_unusable_though_no_uav_held() -> None:
    """Reviews that timed out leave the plan standing (no hold), which would pass as HMAS-2
    run without feedback: over a quarter of them lost refuses the cell; a few do not."""

    def rnd(i: int, errors: int) -> dict[str, Any]:
        reviews = {
            f"uav{u}": {"agree": None, "suggest": None, "error": "LLMTimeout: no answer"}
            if u < errors
            else {"agree": True, "suggest": "A", "error": None}
            for u in range(3)
        }
        return {
            "type": "round",
            "episode": 0,
            "round": i,
            "decisions": {},
            "central": {"calls": [{"stage": "plan"}], "reviews": reviews},
        }

    end = {"type": "episode_end", "episode": 0, "team_return": -1.0, "reason": "horizon"}
    (ok,) = episode_metrics([rnd(0, 1), rnd(1, 0), rnd(2, 0), rnd(3, 0), end])
    assert ok["central_reviews"] == {"asked": 12, "agreed": 11, "disagreed": 0, "failed": 1}
    assert llm_failure_problem([ok]) is None
    (bad,) = episode_metrics([rnd(0, 3), rnd(1, 1), end])
    assert bad["central_reviews"]["failed"] == 4
    problem = llm_failure_problem([bad])
    assert problem is not None
    assert "4 of 6 local reviews" in problem
