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

from aeroweaver_edge.bench.episodes import episode_metrics, read_trace
from aeroweaver_edge.bench.runner import llm_failure_problem
from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm

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
        task="coverage", seed=3, max_rounds=ROUNDS, trace_path=trace, baseline=baseline,
        activation="full", beta=0.0, deadline_s=DEADLINE_S,
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
