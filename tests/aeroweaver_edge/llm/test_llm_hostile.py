"""Hostile endpoints, over real loopback HTTP (``tests.helpers.scripted_http``): JSON nested
100,000 deep and bodies of 50 MB are bad responses (the body read stops at the cap while it
streams in); positive logprobs are no scores; one transient 400 does not switch logprobs
off for the session; httpx's own log lines never show a URL's password or ``?key=``."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

from aeroweaver_edge.agent.llm_selector import LLMSelector
from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.llm.client import (
    MAX_BODY_BYTES,
    CallTag,
    ChatClient,
    LLMBadResponse,
    LLMHTTPError,
)
from aeroweaver_edge.llm.logprobs import parse_label_scores
from aeroweaver_edge.llm.probe import probe_endpoint
from aeroweaver_lab.baselines.json_chat import JsonMode, json_chat
from tests.aeroweaver_edge.agent.test_llm_selector import request
from tests.helpers.scripted_http import Reply, ScriptedHttp, nested_json

ROOT = Path(__file__).resolve().parents[3]
MSGS = [{"role": "user", "content": "pick"}]


def completion(
    content: str = "A", tops: dict[str, float] | None = None, finish: str = "length"
) -> dict[str, object]:
    logprobs = None
    if tops is not None:
        first = next(iter(tops))
        row = {
            "token": first,
            "logprob": tops[first],
            "top_logprobs": [{"token": t, "logprob": v} for t, v in tops.items()],
        }
        logprobs = {"content": [row]}
    return {
        "choices": [
            {"message": {"content": content}, "logprobs": logprobs, "finish_reason": finish}
        ],
        "usage": {"prompt_tokens": 10, "completion_tokens": 1},
    }


# --------------------------------------------------------------- bodies


async def test_deeply_nested_json_is_a_bad_response_and_counts_for_the_breaker() -> None:
    async with ScriptedHttp([Reply(200, nested_json(100_000))]) as srv:
        client = ChatClient(srv.base_url, "m", retries=0, breaker_failures=2)
        for _ in range(2):
            with pytest.raises(LLMBadResponse, match="nested"):
                await client.chat(MSGS)
        assert client.breaker.state == "open"  # the breaker saw both failures
        assert client.requests_sent == 2
        await client.aclose()


async def test_a_50_mb_body_is_refused_while_it_streams_in() -> None:
    async with ScriptedHttp([Reply.stream(50 << 20)]) as srv:
        client = ChatClient(srv.base_url, "m", retries=0, deadline_s=30)
        with pytest.raises(LLMBadResponse, match="over 4 MB"):
            await client.chat(MSGS)
        await client.aclose()
    # the client hung up near the cap: the server could not push the other ~45 MB
    assert srv.sent[0] < MAX_BODY_BYTES + (8 << 20), srv.sent


async def test_a_declared_huge_body_is_not_read_at_all() -> None:
    big = Reply(200, b"{}", headers={"Content-Length": str(50 << 20)})
    async with ScriptedHttp([big]) as srv:
        client = ChatClient(srv.base_url, "m", retries=0, deadline_s=5)
        with pytest.raises(LLMBadResponse, match="over 4 MB"):
            await client.chat(MSGS)
        await client.aclose()


async def test_an_error_body_is_cut_to_its_excerpt() -> None:
    async with ScriptedHttp([Reply.json(400, {"error": {"message": "no " * 2_000_000}})]) as srv:
        client = ChatClient(srv.base_url, "m", retries=0, deadline_s=10)
        with pytest.raises(LLMHTTPError) as info:
            await client.chat(MSGS)
        assert info.value.status == 400
        assert len(str(info.value)) < 400
        await client.aclose()


async def test_the_central_call_counts_the_request_of_a_nested_answer() -> None:
    """Centralized used to report llm_calls 0 for requests that raised RecursionError."""
    async with ScriptedHttp([Reply(200, nested_json(100_000))]) as srv:
        client = ChatClient(srv.base_url, "m", retries=0)
        ans = await json_chat(
            client, MSGS, {"type": "object"}, name="t", max_tokens=8,
            tag=CallTag(), mode=JsonMode(),
        )  # fmt: skip
        assert ans.error is not None
        assert "LLMBadResponse" in ans.error
        assert ans.requests == 1
        await client.aclose()


def test_probe_of_a_nested_answer_exits_with_bad_response_not_a_traceback() -> None:
    import asyncio

    async def serve_and_probe() -> subprocess.CompletedProcess[str]:
        async with ScriptedHttp([Reply(200, nested_json(100_000))]) as srv:
            proc = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "aeroweaver_edge", "probe", "--llm", srv.base_url,
                "--model", "m", stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
                env={**os.environ, "PYTHONPATH": str(ROOT)},
            )  # fmt: skip
            out, err = await asyncio.wait_for(proc.communicate(), 60)
            return subprocess.CompletedProcess([], proc.returncode or 0, out.decode(), err.decode())

    done = asyncio.run(serve_and_probe())
    assert done.returncode == 8, done.stdout + done.stderr
    assert "bad_response" in done.stdout + done.stderr
    assert "Traceback" not in done.stderr


# --------------------------------------------------------------- logprobs


def test_a_positive_logprob_is_no_score() -> None:
    raw = completion("B", {"A": 2.5, "B": -0.1, "C": -3.0})
    scores = parse_label_scores(raw, ["A", "B", "C"], 20)
    assert scores.logprobs == {}
    assert scores.logprobs_usable is False
    assert scores.text_label == "B"  # the generated letter decides
    assert "positive logprob +2.5" in str(scores.extra["unusable"])
    rounding = parse_label_scores(completion("A", {"A": 1e-9, "B": -2.0}), ["A", "B"], 20)
    assert rounding.logprobs_usable
    assert rounding.logprobs["A"] == 0.0  # float noise above 0 is 0


async def test_the_probe_calls_positive_logprobs_degenerate() -> None:
    async with ScriptedHttp([Reply.json(200, completion("A", {"A": 2.5, "B": -1.0}))]) as srv:
        client = ChatClient(srv.base_url, "m", retries=0)
        probe = await probe_endpoint(client, check_tokens=False)
        assert probe.kind == "degenerate"
        assert "positive logprob" in probe.detail
        await client.aclose()


TRANSIENT = Reply.json(400, {"error": {"message": "upstream hiccup, bad request"}})
NAMED = Reply.json(400, {"error": {"message": "'logprobs' is not supported", "param": "x"}})
GOOD = Reply.json(200, completion("C", {"C": -0.1, "A": -3.0, "B": -4.0}))
PLAIN = Reply.json(200, completion("C"))


def selector(srv: ScriptedHttp) -> LLMSelector:
    cfg = LLMConfig(base_url=srv.base_url, model="m", deadline_s=5, retries=0)
    return LLMSelector(ChatClient.from_config(cfg), cfg, None)


async def test_one_transient_400_does_not_switch_logprobs_off() -> None:
    async with ScriptedHttp([TRANSIENT, PLAIN, GOOD]) as srv:
        sel = selector(srv)
        first = await sel.score(request())
        assert first.error is None
        assert first.text_label == "C"  # this round: the plain answer's letter
        assert not sel.settled
        second = await sel.score(request())
        assert sel.llm_class == "ok"
        assert second.logprobs_usable
        assert "logprobs" in srv.requests[-1]  # still asked with logprobs
        await sel.aclose()


async def test_a_refusal_that_repeats_or_names_logprobs_switches_them_off() -> None:
    async with ScriptedHttp([TRANSIENT, PLAIN, TRANSIENT, PLAIN, PLAIN]) as srv:
        sel = selector(srv)
        await sel.score(request())
        await sel.score(request())
        assert sel.llm_class == "rejected"
        assert "2 times" in (sel.probe.detail if sel.probe else "")
        await sel.score(request())
        assert "logprobs" not in srv.requests[-1]
        await sel.aclose()
    async with ScriptedHttp([NAMED, PLAIN, PLAIN]) as srv:
        sel = selector(srv)
        await sel.score(request())
        assert sel.llm_class == "rejected"
        await sel.aclose()


async def test_the_probe_asks_again_after_one_unexplained_refusal() -> None:
    async with ScriptedHttp([TRANSIENT, PLAIN, GOOD]) as srv:
        client = ChatClient(srv.base_url, "m", retries=0)
        probe = await probe_endpoint(client, check_tokens=False)
        assert probe.kind in ("ok", "low_label_mass")
        await client.aclose()
    async with ScriptedHttp([TRANSIENT, PLAIN, TRANSIENT, PLAIN]) as srv:
        client = ChatClient(srv.base_url, "m", retries=0)
        probe = await probe_endpoint(client, check_tokens=False)
        assert probe.kind == "rejected"
        await client.aclose()


# --------------------------------------------------------------- logs

SECRET_PW = "pw-Sup3rSecret"
SECRET_KEY = "k3y-0123456789"


async def test_httpx_log_lines_never_show_url_secrets(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    async with ScriptedHttp([Reply.json(200, completion())]) as srv:
        url = f"http://alice:{SECRET_PW}@127.0.0.1:{srv.port}/v1?key={SECRET_KEY}"
        client = ChatClient(url, "m", retries=0)
        await client.chat(MSGS)
        await client.aclose()
    lines = [r.getMessage() for r in caplog.records]
    http = [line for line in lines if "HTTP Request" in line]
    assert http, lines  # httpx did log the request ...
    assert all("127.0.0.1" in line for line in http)
    joined = "\n".join(lines)
    assert SECRET_PW not in joined  # ... without its secrets
    assert SECRET_KEY not in joined


def test_the_cli_under_v_prints_no_url_secrets() -> None:
    import asyncio

    async def go() -> str:
        async with ScriptedHttp([Reply.json(200, completion("A", {"A": -0.1}))]) as srv:
            url = f"http://alice:{SECRET_PW}@127.0.0.1:{srv.port}/v1?key={SECRET_KEY}"
            proc = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "aeroweaver_edge", "-v", "probe", "--llm", url,
                "--model", "m", stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
                env={**os.environ, "PYTHONPATH": str(ROOT)},
            )  # fmt: skip
            out, err = await asyncio.wait_for(proc.communicate(), 60)
            return out.decode() + err.decode()

    text = asyncio.run(go())
    assert "HTTP Request: POST" in text  # -v shows httpx's lines
    assert SECRET_PW not in text
    assert SECRET_KEY not in text
