"""ChatClient against a real loopback HTTP server: budgets, retries, breaker, usage, ledger."""

from __future__ import annotations

import asyncio
import socket
import time
from collections.abc import AsyncIterator

import pytest

from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.llm.client import (
    CallTag,
    ChatClient,
    CircuitBreaker,
    LLMBadResponse,
    LLMBreakerOpen,
    LLMConfigError,
    LLMHTTPError,
    LLMTimeout,
    LLMUnreachable,
    Usage,
    UsageLedger,
)
from aeroweaver_edge.llm.fake_provider import QUIRKS, FakeProvider, Policy

MSGS = [{"role": "user", "content": "A. go\nB. stay\nAnswer with one letter."}]


@pytest.fixture
async def fp() -> AsyncIterator[FakeProvider]:
    async with FakeProvider(Policy(prefer="B")) as server:
        yield server


def client_for(url: str, **kw: object) -> ChatClient:
    defaults: dict[str, object] = {"deadline_s": 2.0, "retries": 1, "backoff_s": 0.01}
    defaults.update(kw)
    return ChatClient(url, "fake-model", **defaults)  # type: ignore[arg-type]


def closed_port_url() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    return f"http://127.0.0.1:{port}/v1"


# ------------------------------------------------------------------ happy path


async def test_chat_returns_raw_usage_and_latency(fp: FakeProvider) -> None:
    async with client_for(fp.base_url) as client:
        result = await client.chat(MSGS, max_tokens=1, logprobs=True, top_logprobs=5)
    assert result.raw["choices"][0]["message"]["content"] == "B"
    assert result.usage.prompt_tokens > 0
    assert result.usage.completion_tokens == 1
    assert result.latency_s > 0
    assert result.attempts == 1
    body = fp.chat_bodies()[0]
    assert body["model"] == "fake-model"
    assert body["max_tokens"] == 1
    assert body["stream"] is False


async def test_extra_body_is_merged_last(fp: FakeProvider) -> None:
    extra = {"thinking": {"type": "disabled"}, "temperature": 1.0}
    async with client_for(fp.base_url, extra_body=extra) as client:
        await client.chat(MSGS, temperature=0.0)
    body = fp.chat_bodies()[0]
    assert body["thinking"] == {"type": "disabled"}
    assert body["temperature"] == 1.0


async def test_api_key_is_sent_and_never_shown(
    fp: FakeProvider, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("AW_TEST_KEY", "sk-secret-123")
    client = client_for(fp.base_url, api_key_env="AW_TEST_KEY")
    try:
        await client.chat(MSGS)
        assert "sk-secret-123" not in repr(client)
    finally:
        await client.aclose()
    assert fp.requests[0].headers["authorization"] == "Bearer sk-secret-123"


def test_missing_api_key_variable_is_a_config_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("AW_NO_SUCH_KEY", raising=False)
    with pytest.raises(LLMConfigError, match="AW_NO_SUCH_KEY"):
        client_for("http://127.0.0.1:9/v1", api_key_env="AW_NO_SUCH_KEY")


async def test_from_config_uses_every_budget(fp: FakeProvider) -> None:
    cfg = LLMConfig(model="m1", deadline_s=3.5, retries=2, breaker_failures=4, breaker_reset_s=7)
    client = ChatClient.from_config(cfg, base_url=fp.base_url)
    try:
        assert (client.model, client.deadline_s, client.retries) == ("m1", 3.5, 2)
        assert (client.breaker.threshold, client.breaker.reset_s) == (4, 7)
    finally:
        await client.aclose()
    with pytest.raises(LLMConfigError, match="base_url"):
        ChatClient.from_config(LLMConfig())


# ------------------------------------------------------------------ retries


@pytest.mark.parametrize("status", [429, 500, 503])
async def test_transient_status_is_retried(fp: FakeProvider, status: int) -> None:
    fp.policy = Policy(status=status, status_times=1)
    async with client_for(fp.base_url, retries=1) as client:
        result = await client.chat(MSGS)
    assert result.attempts == 2
    assert fp.chat_calls == 2


async def test_retries_are_bounded_and_the_error_names_status_body_and_endpoint(
    fp: FakeProvider,
) -> None:
    fp.policy = QUIRKS["server_error"]
    async with client_for(fp.base_url, retries=2) as client:
        with pytest.raises(LLMHTTPError) as info:
            await client.chat(MSGS)
    assert fp.chat_calls == 3
    assert info.value.status == 503
    assert "scripted HTTP 503" in info.value.body
    assert fp.base_url in str(info.value)


async def test_client_errors_are_not_retried(fp: FakeProvider) -> None:
    fp.policy = QUIRKS["reject_logprobs"]
    async with client_for(fp.base_url, retries=3) as client:
        with pytest.raises(LLMHTTPError, match="not supported") as info:
            await client.chat(MSGS, logprobs=True, top_logprobs=20)
    assert info.value.status == 400
    assert fp.chat_calls == 1


async def test_retry_never_sleeps_past_the_deadline(fp: FakeProvider) -> None:
    fp.policy = Policy(status=429, retry_after=30)
    async with client_for(fp.base_url, retries=3, deadline_s=1.0) as client:
        started = time.perf_counter()
        with pytest.raises(LLMHTTPError, match="429"):
            await client.chat(MSGS)
    assert time.perf_counter() - started < 0.9  # gave up at once: neither 30 s nor the 1 s deadline
    assert fp.chat_calls == 1


async def test_endpoint_down_fails_fast() -> None:
    async with client_for(closed_port_url(), retries=2, deadline_s=5.0) as client:
        started = time.perf_counter()
        with pytest.raises(LLMUnreachable, match=r"cannot connect to http://127\.0\.0\.1"):
            await client.chat(MSGS)
    assert time.perf_counter() - started < 2.0  # far inside the 5 s deadline


async def test_hanging_endpoint_times_out_inside_the_deadline(fp: FakeProvider) -> None:
    fp.policy = QUIRKS["hang"]
    async with client_for(fp.base_url, deadline_s=0.5, retries=2) as client:
        started = time.perf_counter()
        with pytest.raises(LLMTimeout, match=r"within the 0.5 s deadline"):
            await client.chat(MSGS)
    elapsed = time.perf_counter() - started
    assert 0.45 < elapsed < 1.5


async def test_slow_drip_is_bounded_by_the_whole_call_deadline(fp: FakeProvider) -> None:
    fp.policy = Policy(drip_s=0.05)  # every chunk arrives well within any read timeout
    async with client_for(fp.base_url, deadline_s=0.6) as client:
        started = time.perf_counter()
        with pytest.raises(LLMTimeout):
            await client.chat(MSGS, logprobs=True, top_logprobs=20)
    assert time.perf_counter() - started < 1.5


async def test_per_call_deadline_override(fp: FakeProvider) -> None:
    fp.policy = QUIRKS["hang"]
    async with client_for(fp.base_url, deadline_s=30) as client:
        with pytest.raises(LLMTimeout, match=r"0\.3 s"):
            await client.chat(MSGS, deadline_s=0.3)


async def test_per_call_deadline_longer_than_the_clients(fp: FakeProvider) -> None:
    fp.policy = Policy(delay_s=1.3)  # past the client's own httpx timeout (0.1 + 1 s)
    async with client_for(fp.base_url, deadline_s=0.1) as client:
        with pytest.raises(LLMTimeout):
            await client.chat(MSGS)
        result = await client.chat(MSGS, deadline_s=3.0)  # httpx must not time out first
    assert result.usage.prompt_tokens > 0


async def test_non_json_answer_is_a_bad_response(fp: FakeProvider) -> None:
    fp.policy = QUIRKS["bad_json"]
    async with client_for(fp.base_url) as client:
        with pytest.raises(LLMBadResponse, match="non-JSON"):
            await client.chat(MSGS)


# ------------------------------------------------------------------ breaker


def state_of(client: ChatClient) -> str:
    return client.breaker.state  # a call, so mypy does not narrow across awaits


async def test_breaker_opens_fails_fast_then_half_opens(fp: FakeProvider) -> None:
    fp.policy = QUIRKS["server_error"]
    client = client_for(fp.base_url, retries=0, breaker_failures=2, breaker_reset_s=0.3)
    try:
        for _ in range(2):
            with pytest.raises(LLMHTTPError):
                await client.chat(MSGS)
        assert state_of(client) == "open"
        calls = len(fp.requests)
        with pytest.raises(LLMBreakerOpen, match="circuit breaker open for http") as info:
            await client.chat(MSGS)
        assert len(fp.requests) == calls  # it failed fast: no request went out
        assert "2 consecutive failures" in str(info.value)
        # still failing after the reset time: the single trial re-opens the breaker
        await asyncio.sleep(0.35)
        assert state_of(client) == "half_open"
        with pytest.raises(LLMHTTPError):
            await client.chat(MSGS)
        assert state_of(client) == "open"
        # endpoint recovers: the next trial closes it
        fp.policy = Policy()
        await asyncio.sleep(0.35)
        await client.chat(MSGS)
        assert state_of(client) == "closed"
    finally:
        await client.aclose()


async def test_breaker_ignores_client_errors(fp: FakeProvider) -> None:
    fp.policy = QUIRKS["reject_logprobs"]
    async with client_for(fp.base_url, breaker_failures=1) as client:
        for _ in range(3):
            with pytest.raises(LLMHTTPError):
                await client.chat(MSGS, logprobs=True)
        assert client.breaker.state == "closed"


def test_breaker_lets_exactly_one_trial_through_when_half_open() -> None:
    now = [0.0]
    breaker = CircuitBreaker(failures=1, reset_s=5.0, clock=lambda: now[0])
    breaker.failure("boom")
    with pytest.raises(LLMBreakerOpen, match=r"next trial in 5.0 s"):
        breaker.before_call("http://x")
    now[0] = 5.0
    breaker.before_call("http://x")  # the trial
    with pytest.raises(LLMBreakerOpen):
        breaker.before_call("http://x")  # concurrent callers still fail fast
    breaker.success()
    breaker.before_call("http://x")
    assert breaker.state == "closed"


async def test_cancelled_trial_releases_the_half_open_slot(fp: FakeProvider) -> None:
    client = client_for(fp.base_url, breaker_failures=1, breaker_reset_s=0.01, deadline_s=5)
    try:
        client.breaker.failure("earlier failure")
        await asyncio.sleep(0.02)
        fp.policy = QUIRKS["hang"]
        task = asyncio.create_task(client.chat(MSGS))
        await asyncio.sleep(0.1)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        fp.policy = Policy()
        await client.chat(MSGS)  # a new trial is allowed and succeeds
        assert client.breaker.state == "closed"
    finally:
        await client.aclose()


# ------------------------------------------------------------------ usage and ledger


def test_usage_shapes() -> None:
    openai = {
        "usage": {
            "prompt_tokens": 100,
            "completion_tokens": 1,
            "total_tokens": 101,
            "prompt_tokens_details": {"cached_tokens": 64},
            "completion_tokens_details": {"reasoning_tokens": 0},
        }
    }
    deepseek = {
        "usage": {
            "prompt_tokens": 100,
            "completion_tokens": 5,
            "prompt_cache_hit_tokens": 80,
            "prompt_cache_miss_tokens": 20,
            "completion_tokens_details": {"reasoning_tokens": 4},
        }
    }
    llama = {
        "usage": {"prompt_tokens": 50, "completion_tokens": 1},
        "timings": {"cache_n": 49, "prompt_n": 1},
    }
    assert Usage.from_response(openai) == Usage(100, 1, 64, 0)
    assert Usage.from_response(deepseek) == Usage(100, 5, 80, 4)
    assert Usage.from_response(llama) == Usage(50, 1, 49, 0)
    assert Usage.from_response({}) == Usage()
    assert (
        Usage.from_response({"usage": {"prompt_tokens": None, "completion_tokens": "x"}}) == Usage()
    )


@pytest.mark.parametrize("shape", ["openai", "deepseek", "llama"])
async def test_cached_tokens_come_back_for_every_usage_shape(fp: FakeProvider, shape: str) -> None:
    fp.policy = Policy(usage=shape)  # type: ignore[arg-type]
    async with client_for(fp.base_url) as client:
        first = await client.chat(MSGS)
        second = await client.chat(MSGS)
    assert first.usage.cached_tokens == 0
    assert second.usage.cached_tokens == second.usage.prompt_tokens > 0


async def test_ledger_sums_per_agent_role_episode_and_counts_errors(fp: FakeProvider) -> None:
    ledger = UsageLedger()
    async with client_for(fp.base_url, ledger=ledger, retries=0) as client:
        await client.chat(MSGS, tag=CallTag("uav1", "searcher", 1, 0))
        await client.chat(MSGS, tag=CallTag("uav1", "searcher", 1, 1))
        await client.chat(MSGS, tag=CallTag("uav2", "relay", 2, 0))
        fp.policy = QUIRKS["server_error"]
        with pytest.raises(LLMHTTPError):
            await client.chat(MSGS, tag=CallTag("uav2", "relay", 2, 1))
    assert len(ledger.journal) == 4
    assert ledger.total.calls == 4
    assert ledger.total.errors == 1
    uav1 = ledger.by_agent()["uav1"]
    assert uav1.calls == 2
    assert uav1.completion_tokens == 2
    assert uav1.prompt_tokens == sum(e.usage.prompt_tokens for e in ledger.journal[:2])
    assert ledger.by_role()["relay"].errors == 1
    assert ledger.by_episode()[2].calls == 2
    assert ledger.totals_for(agent="uav2", episode=2).calls == 2
    failed = ledger.journal[-1]
    assert (failed.ok, failed.error, failed.usage.total_tokens) == (False, "LLMHTTPError", 0)
    assert ledger.total.latency_s > 0


async def test_ledger_sums_survive_a_bounded_journal(fp: FakeProvider) -> None:
    ledger = UsageLedger(max_journal=2)
    async with client_for(fp.base_url, ledger=ledger) as client:
        for _ in range(5):
            await client.chat(MSGS, tag=CallTag("uav1"))
    assert len(ledger.journal) == 2
    assert ledger.by_agent()["uav1"].calls == 5


async def test_breaker_refusals_are_journaled(fp: FakeProvider) -> None:
    async with client_for(fp.base_url, breaker_failures=1, retries=0) as client:
        fp.policy = QUIRKS["server_error"]
        with pytest.raises(LLMHTTPError):
            await client.chat(MSGS)
        with pytest.raises(LLMBreakerOpen):
            await client.chat(MSGS)
        assert [e.error for e in client.ledger.journal] == ["LLMHTTPError", "LLMBreakerOpen"]


# ------------------------------------------------------------------ tokenize


async def test_tokenize_single_split_and_absent(fp: FakeProvider) -> None:
    async with client_for(fp.base_url) as client:
        assert await client.tokenize("A") == [49]
        assert await client.tokenize("H") == [56]
        fp.policy = Policy(tokenizer="split")
        tokens = await client.tokenize("A")
        assert tokens is not None
        assert len(tokens) == 2
        fp.policy = Policy(tokenizer="absent")
        assert await client.tokenize("A") is None
    assert fp.requests[-1].path == "/tokenize"


async def test_tokenize_against_a_down_endpoint_raises() -> None:
    async with client_for(closed_port_url()) as client:
        with pytest.raises(LLMUnreachable, match="/tokenize"):
            await client.tokenize("A")
