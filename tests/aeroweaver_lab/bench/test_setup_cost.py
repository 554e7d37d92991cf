"""One LLM Commander activation per task, measured on a real loopback endpoint."""

from __future__ import annotations

import socket

from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
from aeroweaver_lab.bench.setup_cost import measure_one


async def test_a_parse_and_roles_call_are_counted() -> None:
    async with FakeProvider(Policy(prefer="A"), n_slots=2) as fp:
        llm = LLMConfig(base_url=fp.base_url, model=fp.model, deadline_s=10.0)
        entry = await measure_one("line_formation", llm)
    assert entry["error"] is None
    # the fake provider's answer is no task record: the parser falls back to rules, but the
    # call was made and its tokens reported, so that is the setup's cost
    assert entry["parse_source"] in ("llm", "fallback")
    assert entry["setup_tokens"] > 0
    assert entry["mission_text"]


async def test_an_endpoint_that_fails_is_no_measurement_not_zero_tokens() -> None:
    with socket.socket() as s:  # a port nobody listens on: connection refused
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    llm = LLMConfig(base_url=f"http://127.0.0.1:{port}/v1", model="m", deadline_s=2.0)
    entry = await measure_one("coverage", llm)
    assert entry["setup_tokens"] is None
    assert "parse call failed" in entry["error"]
