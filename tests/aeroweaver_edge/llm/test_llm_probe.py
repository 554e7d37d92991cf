"""Endpoint probe: each classification against the real loopback fake."""

from __future__ import annotations

import socket
from collections.abc import AsyncIterator

import pytest

from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.llm.fake_provider import QUIRKS, FakeProvider, Policy
from aeroweaver_edge.llm.probe import PROBE_LABELS, ProbeResult, probe_endpoint


@pytest.fixture
async def fp() -> AsyncIterator[FakeProvider]:
    async with FakeProvider() as server:
        yield server


async def probe(url: str, **kw: object) -> ProbeResult:
    async with ChatClient(url, "fake", deadline_s=0.5, retries=0) as client:
        return await probe_endpoint(client, **kw)  # type: ignore[arg-type]


async def test_ok(fp: FakeProvider) -> None:
    result = await probe(fp.base_url)
    assert result.kind == "ok"
    assert result.ok
    assert result.correction_on
    assert 0.3 < result.label_mass <= 1.0
    assert result.single_token_labels is not None
    assert set(PROBE_LABELS) <= set(result.single_token_labels)
    body = fp.chat_bodies()[0]
    assert (body["max_tokens"], body["logprobs"], body["top_logprobs"]) == (1, True, 20)
    line = result.line()
    assert line.startswith("LLM probe [ok] fake @ http://127.0.0.1")
    assert "correction ON" in line
    assert "\n" not in line


@pytest.mark.parametrize("quirk", ["reject_logprobs", "ignore_logprobs"])
async def test_rejected(fp: FakeProvider, quirk: str) -> None:
    fp.policy = QUIRKS[quirk]
    result = await probe(fp.base_url)
    assert result.kind == "rejected"
    assert not result.correction_on
    assert "correction OFF" in result.line()
    assert "generated text label" in result.line()


async def test_rejected_detail_names_the_providers_message(fp: FakeProvider) -> None:
    fp.policy = QUIRKS["reject_logprobs"]
    result = await probe(fp.base_url)
    assert "HTTP 400" in result.detail
    assert "not supported" in result.detail


@pytest.mark.parametrize("quirk", ["degenerate", "degenerate_empty"])
async def test_degenerate(fp: FakeProvider, quirk: str) -> None:
    fp.policy = QUIRKS[quirk]
    result = await probe(fp.base_url)
    assert result.kind == "degenerate"
    assert result.label_mass == 0.0


async def test_low_label_mass(fp: FakeProvider) -> None:
    fp.policy = Policy(missing=PROBE_LABELS)  # a base model: labels far down the list
    result = await probe(fp.base_url)
    assert result.kind == "low_label_mass"
    assert result.label_mass < 0.3
    assert "0.30" in result.detail


async def test_threshold_is_configurable(fp: FakeProvider) -> None:
    assert (await probe(fp.base_url, min_label_mass=0.999)).kind == "low_label_mass"


@pytest.mark.parametrize(
    ("quirk", "kind"),
    [
        ("hang", "timeout"),
        ("server_error", "server_error"),
        ("rate_limited", "server_error"),
        ("bad_json", "bad_response"),
    ],
)
async def test_no_verdict_kinds(fp: FakeProvider, quirk: str, kind: str) -> None:
    fp.policy = QUIRKS[quirk]
    result = await probe(fp.base_url)
    assert result.kind == kind
    assert not result.verdict
    assert result.detail
    assert "no verdict on logprobs yet" in result.line()
    assert "correction OFF" not in result.line()  # the first answer will decide it


async def test_unreachable_when_nothing_listens() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    result = await probe(f"http://127.0.0.1:{port}/v1")
    assert result.kind == "unreachable"
    assert "LLMUnreachable" in result.detail
    assert f"127.0.0.1:{port}" in result.line()


async def test_multi_token_labels_are_reported(fp: FakeProvider) -> None:
    fp.policy = Policy(tokenizer="split")
    result = await probe(fp.base_url)
    assert result.single_token_labels == ()
    assert "labels not single tokens: ABCDEFGH" in result.detail


async def test_no_tokenize_route_means_unknown(fp: FakeProvider) -> None:
    fp.policy = Policy(tokenizer="absent")
    result = await probe(fp.base_url)
    assert result.kind == "ok"
    assert result.single_token_labels is None
