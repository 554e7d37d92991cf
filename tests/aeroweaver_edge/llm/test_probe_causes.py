"""The LLM layer against a hostile endpoint: each failure classified by what the endpoint
says (real loopback fake), requests counted, credentials never printed."""

from __future__ import annotations

import socket
from collections.abc import AsyncIterator

import pytest

from aeroweaver_edge.agent.llm_selector import LLMSelector
from aeroweaver_edge.agent.scoring import choose
from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.contracts.observation import Observation, VehicleState
from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest
from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.llm.fake_provider import QUIRKS, FakeProvider, Policy
from aeroweaver_edge.llm.probe import EXIT_STATUS, ProbeResult, probe_endpoint
from aeroweaver_edge.runtime.redact import redact_url

CANDIDATES = [
    Candidate("A", "cover_landmark", {"target_id": "L1"}, "cover_landmark(target_id=L1)"),
    Candidate("B", "explore_local", {"heading": "north"}, "explore_local(heading=north)"),
    Candidate("C", "hold_position", {}, "hold_position()"),
]
LABELS = [c.label for c in CANDIDATES]


def request() -> DecisionRequest:
    obs = Observation(
        uav="uav1", episode=0, round=1, own=VehicleState(pos=(0.0, 0.0, -5.0), vel=(0.0, 0.0, 0.0))
    )
    return DecisionRequest(
        observation=obs,
        mission_text="Cover every landmark.",
        role="searcher",
        local_goal="Take the nearest unclaimed landmark.",
        constraints=(),
        skill_docs=("### cover_landmark\nFly to a landmark.", "### hold_position\nStay."),
        observation_text="round 1; landmark L1: 20 m N",
        candidates=CANDIDATES,
    )


@pytest.fixture
async def fp() -> AsyncIterator[FakeProvider]:
    async with FakeProvider() as server:
        yield server


async def probe(url: str, model: str = "fake-model", **kw: object) -> ProbeResult:
    async with ChatClient(url, model, deadline_s=0.5, retries=0, **kw) as client:  # type: ignore[arg-type]
        return await probe_endpoint(client, check_tokens=False)


def closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.parametrize(
    ("quirk", "kind", "needle"),
    [
        ("unauthorized", "auth", "Incorrect API key"),
        ("forbidden", "auth", "no access"),
        ("wrong_model", "not_found", "does not exist"),
        ("wrong_model_400", "bad_request", "Model Not Exist"),
        ("context_length", "bad_request", "maximum context length"),
        ("reject_logprobs", "rejected", "not supported"),
        ("hang", "timeout", "deadline"),
        ("server_error", "server_error", "503"),
    ],
)
async def test_probe_names_the_cause(fp: FakeProvider, quirk: str, kind: str, needle: str) -> None:
    fp.policy = QUIRKS[quirk]
    result = await probe(fp.base_url, model="other-model" if "model" in quirk else "fake-model")
    assert result.kind == kind
    assert needle in result.detail
    assert result.exit_status == EXIT_STATUS[kind]
    line = result.line()
    assert "\n" not in line
    assert f"[{kind}]" in line


async def test_context_length_is_not_read_as_logprobs_refused(fp: FakeProvider) -> None:
    """Issue 8: any 400 switched logprobs off. The probe asks again without them: the
    400 stays, so it says bad_request and leaves the logprob question open."""
    fp.policy = QUIRKS["context_length"]
    result = await probe(fp.base_url)
    bodies = fp.chat_bodies()
    assert len(bodies) == 2
    assert "logprobs" in bodies[0]
    assert "logprobs" not in bodies[1]
    assert result.kind == "bad_request"
    assert not result.verdict


async def test_right_key_passes_the_auth_quirk(
    fp: FakeProvider, monkeypatch: pytest.MonkeyPatch
) -> None:
    fp.policy = QUIRKS["unauthorized"]
    monkeypatch.setenv("AW_TEST_KEY", "sk-right-key")
    assert (await probe(fp.base_url, api_key_env="AW_TEST_KEY")).kind == "ok"
    monkeypatch.setenv("AW_TEST_KEY", "sk-wrong-key")
    wrong = await probe(fp.base_url, api_key_env="AW_TEST_KEY")
    assert wrong.kind == "auth"
    assert "sk-wrong-key" not in wrong.line()


async def test_connection_refused_and_dns_are_unreachable() -> None:
    refused = await probe(f"http://127.0.0.1:{closed_port()}/v1")
    assert (refused.kind, refused.exit_status) == ("unreachable", 6)
    dns = await probe("http://no-such-host.invalid/v1")
    assert dns.kind == "unreachable"
    assert "no-such-host.invalid" in dns.line()


def test_exit_statuses_are_distinct_per_failure_class() -> None:
    failures = {k: v for k, v in EXIT_STATUS.items() if k not in {"ok"}}
    assert EXIT_STATUS["ok"] == 0
    assert 1 not in failures.values()
    assert 2 not in failures.values()
    assert len({failures[k] for k in ("auth", "not_found", "unreachable", "timeout")}) == 4
    assert {failures[k] for k in ("rejected", "degenerate", "low_label_mass")} == {3}


# ---------------------------------------------------------------- the selector


def make_selector(fp: FakeProvider, probe_result: ProbeResult | None) -> LLMSelector:
    cfg = LLMConfig(base_url=fp.base_url, model="fake-model", deadline_s=1.0, retries=0)
    return LLMSelector(ChatClient.from_config(cfg), cfg, probe_result)


async def test_unsettled_selector_keeps_logprobs_after_a_context_length_400(
    fp: FakeProvider,
) -> None:
    fp.policy = Policy(prefer="C", max_prompt_chars=200)
    sel = make_selector(fp, None)
    try:
        failed = await sel.score(request())
        assert failed.error is not None
        assert "maximum context length" in failed.error
        assert sel.probe is None  # nothing learnt about logprobs
        assert sel.requests_sent == 2
        fp.policy = Policy(prefer="C")  # the prompt fits again (e.g. fewer messages)
        scores = await sel.score(request())
    finally:
        await sel.aclose()
    assert sel.probe is not None
    assert sel.probe.kind == "ok"
    assert scores.logprobs_usable
    assert choose(scores, LABELS, {}, beta=0.8).label == "C"
    assert "logprobs" in fp.chat_bodies()[-1]


async def test_settled_selector_does_not_retry_a_400(fp: FakeProvider) -> None:
    fp.policy = Policy(max_prompt_chars=200)
    sel = make_selector(fp, ProbeResult("ok", 0.9))
    try:
        scores = await sel.score(request())
    finally:
        await sel.aclose()
    assert scores.error is not None
    assert scores.extra["probe"] == "ok"
    assert sel.requests_sent == 1
    assert sel.probe is not None
    assert sel.probe.kind == "ok"


async def test_every_request_is_counted_even_without_usage(fp: FakeProvider) -> None:
    fp.policy = QUIRKS["server_error"]
    cfg = LLMConfig(base_url=fp.base_url, model="fake-model", deadline_s=2.0, retries=1)
    client = ChatClient.from_config(cfg)
    client.backoff_s = 0.0
    sel = LLMSelector(client, cfg, ProbeResult("ok", 0.9))
    try:
        scores = await sel.score(request())
    finally:
        await sel.aclose()
    assert scores.error is not None
    assert scores.prompt_tokens == 0
    assert sel.requests_sent == 2 == fp.chat_calls  # the request and its retry
    entry = client.ledger.journal[-1]
    assert (entry.ok, entry.attempts) == (False, 2)


# ---------------------------------------------------------------- credentials


@pytest.mark.parametrize(
    ("url", "shown", "hidden"),
    [
        ("https://bob:hunter2secret@api.example.com/v1", "https://***@api.example.com/v1",
         "hunter2secret"),
        ("http://h:8080/v1?api_key=sk-abc123&v=2", "http://h:8080/v1?api_key=***&v=2",
         "sk-abc123"),
        ("http://h/v1?Api-Key=sk-xyz789", "http://h/v1?Api-Key=***", "sk-xyz789"),
    ],
)  # fmt: skip
def test_redact_url(url: str, shown: str, hidden: str) -> None:
    assert redact_url(url) == shown
    assert hidden not in redact_url(url)


async def test_credentials_in_the_base_url_never_reach_errors_or_the_probe_line(
    fp: FakeProvider,
) -> None:
    secret = "sk-query-secret-42"
    url = f"http://user:pw-secret-99@127.0.0.1:{fp.port}/v1?api_key={secret}"
    fp.policy = QUIRKS["echo_target"]  # a 404 whose body echoes the full request target
    async with ChatClient(url, "fake-model", deadline_s=1.0, retries=0) as client:
        assert secret not in client.endpoint
        assert "pw-secret-99" not in client.endpoint
        result = await probe_endpoint(client, check_tokens=False)
        assert client.requests_sent == 1
    assert result.kind == "not_found"
    text = result.line() + result.detail + repr(result)
    assert secret not in text
    assert "pw-secret-99" not in text
    assert "no route for POST /v1/chat/completions?api_key=***" in result.detail  # echoed, masked
    # the key really went to the endpoint, as a query parameter of the request
    assert fp.requests[-1].path == "/v1/chat/completions"
    fp.policy = Policy()
    async with ChatClient(url, "fake-model", deadline_s=1.0, retries=0) as client:
        assert (await probe_endpoint(client, check_tokens=False)).kind == "ok"
