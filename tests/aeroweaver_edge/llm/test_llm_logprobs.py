"""Parsing chat completions into LabelScores: hand-made shapes and every quirk of the fake."""

from __future__ import annotations

import math
from collections.abc import AsyncIterator
from typing import Any

import pytest

from aeroweaver_edge.agent.scoring import NOT_OBSERVED, choose
from aeroweaver_edge.llm.client import ChatClient, Usage
from aeroweaver_edge.llm.fake_provider import QUIRKS, FakeProvider, Policy
from aeroweaver_edge.llm.logprobs import label_mass, normalise_token, parse_label_scores

LABELS = list("ABCD")
ln = math.log


def completion(
    tops: list[tuple[str, float]] | None,
    *,
    chosen: tuple[str, float] | None = None,
    content: str | None = "A",
    finish: str | None = "length",
    **row_extra: Any,
) -> dict[str, Any]:
    """A minimal OpenAI-shaped completion with one content row."""
    logprobs: dict[str, Any] | None = None
    if tops is not None:
        tok, lp = chosen if chosen is not None else (tops[0] if tops else ("A", 0.0))
        row = {"token": tok, "logprob": lp, "bytes": None, **row_extra}
        row["top_logprobs"] = [{"token": t, "logprob": v, "bytes": None} for t, v in tops]
        logprobs = {"content": [row], "refusal": None}
    return {
        "choices": [
            {
                "index": 0,
                "message": {"role": "assistant", "content": content},
                "logprobs": logprobs,
                "finish_reason": finish,
            }
        ]
    }


# ------------------------------------------------------------------ normalisation


@pytest.mark.parametrize(
    ("token", "expected"),
    [("A", "A"), (" A", "A"), ("a", "A"), (" b", "B"), ("\nC", "C"), ("An", "An"),
     (" answer", "answer"), ("1", "1"), ("É", "É"), ("", "")],
)  # fmt: skip
def test_normalise_token(token: str, expected: str) -> None:
    assert normalise_token(token) == expected


# ------------------------------------------------------------------ hand-made shapes


def test_plain_labels_and_bound_over_all_entries() -> None:
    tops = [("A", ln(0.5)), ("The", ln(0.2)), ("B", ln(0.1)), ("C", ln(0.05))]
    s = parse_label_scores(completion(tops), LABELS, requested=4)
    assert s.logprobs == pytest.approx({"A": ln(0.5), "B": ln(0.1), "C": ln(0.05)})
    assert s.logprobs_usable
    # full list (4 of 4): floor 0.05 is below the leftover 0.15; "The" counted too
    assert s.omitted_bound == pytest.approx(ln(0.05))
    assert s.text_label == "A"
    assert s.extra["label_mass"] == pytest.approx(0.65)


def test_variants_fold_with_logsumexp() -> None:
    tops = [(" B", ln(0.4)), ("B", ln(0.2)), ("b", ln(0.1)), ("A", ln(0.1))]
    s = parse_label_scores(completion(tops, content=" B"), LABELS, requested=20)
    assert s.logprobs["B"] == pytest.approx(ln(0.7))
    assert s.logprobs["A"] == pytest.approx(ln(0.1))
    assert s.text_label == "B"
    assert label_mass(s.logprobs) == pytest.approx(0.8)


def test_multi_character_tokens_never_match_a_label() -> None:
    tops = [("An", ln(0.6)), ("Answer", ln(0.2)), ("B", ln(0.1))]
    s = parse_label_scores(completion(tops, content="An"), LABELS, requested=3)
    assert set(s.logprobs) == {"B"}
    assert choose(s, LABELS, {}, 0.0).label == "B"


def test_minus_9999_is_not_observed() -> None:
    tops = [("A", ln(0.5)), ("B", NOT_OBSERVED), ("C", ln(0.2)), ("x", NOT_OBSERVED)]
    s = parse_label_scores(completion(tops), LABELS, requested=4)
    assert set(s.logprobs) == {"A", "C"}
    # floors neither fill the list nor count as a floor: leftover 0.3 bounds B
    assert s.omitted_bound == pytest.approx(ln(0.3))


def test_fewer_entries_than_requested_use_leftover_mass() -> None:
    tops = [("A", ln(0.6)), ("B", ln(0.3))]
    s = parse_label_scores(completion(tops), LABELS, requested=20)
    assert s.omitted_bound == pytest.approx(ln(0.1))


def test_sampled_token_outside_the_list_does_not_tighten_the_floor() -> None:
    tops = [("A", ln(0.5)), ("B", ln(0.3))]
    s = parse_label_scores(completion(tops, chosen=("D", ln(0.01))), LABELS, requested=2)
    assert s.logprobs["D"] == pytest.approx(ln(0.01))
    # floor stays 0.3 (from the list); leftover with D seen is 0.19 -> bound 0.19
    assert s.omitted_bound == pytest.approx(ln(0.19))


def test_duplicate_sampled_token_is_counted_once() -> None:
    tops = [("A", ln(0.5)), ("B", ln(0.3)), ("A", ln(0.5))]  # vLLM appends the sampled one
    s = parse_label_scores(completion(tops), LABELS, requested=2)
    assert s.logprobs["A"] == pytest.approx(ln(0.5))
    assert s.omitted_bound == pytest.approx(ln(0.2))


@pytest.mark.parametrize(
    "tops",
    [[], [("A", 0.0)], [("A", 0.0), ("B", NOT_OBSERVED), ("C", NOT_OBSERVED)]],
)
def test_degenerate_rows_fall_back_to_the_text_label(tops: list[tuple[str, float]]) -> None:
    raw = completion(tops, chosen=("A", 0.0), content="a")
    s = parse_label_scores(raw, LABELS, requested=20)
    assert not s.logprobs_usable
    assert s.extra["degenerate"] is True
    assert s.text_label == "A"
    assert choose(s, LABELS, {"B": 5.0}, 0.8).label == "A"


def test_missing_logprobs_fall_back_to_the_text_label() -> None:
    s = parse_label_scores(completion(None, content=" c"), LABELS, requested=20)
    assert not s.logprobs_usable
    assert s.text_label == "C"
    assert "no content logprobs" in str(s.extra["unusable"])


def test_extra_fields_bytes_null_and_reasoning_array_are_tolerated() -> None:
    raw = completion([("A", ln(0.7)), ("B", ln(0.2))], id=49)
    raw["timings"] = {"cache_n": 3}
    raw["choices"][0]["logprobs"]["reasoning_content"] = [
        {"token": "Think", "logprob": -0.1, "bytes": None, "top_logprobs": []}
    ]
    raw["choices"][0]["message"]["reasoning_content"] = "Think"
    s = parse_label_scores(raw, LABELS, requested=20)
    assert s.logprobs == pytest.approx({"A": ln(0.7), "B": ln(0.2)})


def test_only_reasoning_tokens_means_unusable() -> None:
    raw = completion(None, content="")
    raw["choices"][0]["logprobs"] = {"content": [], "reasoning_content": [{"token": "x"}]}
    s = parse_label_scores(raw, LABELS, requested=20)
    assert not s.logprobs_usable
    assert s.text_label is None
    assert choose(s, LABELS, {}, 0.8).label is None


@pytest.mark.parametrize("finish", ["content_filter", "tool_calls"])
def test_unexpected_finish_reason_is_an_error(finish: str) -> None:
    s = parse_label_scores(completion([("A", -0.1)], finish=finish), LABELS, requested=20)
    assert s.error is not None
    assert finish in s.error
    assert choose(s, LABELS, {}, 0.8).label is None


@pytest.mark.parametrize("finish", ["stop", "length", None])
def test_normal_finish_reasons(finish: str | None) -> None:
    s = parse_label_scores(completion([("A", -0.1)], finish=finish), LABELS, requested=20)
    assert s.error is None


def test_garbage_values_are_skipped() -> None:
    raw = completion([("A", ln(0.5))])
    raw["choices"][0]["logprobs"]["content"][0]["top_logprobs"] += [
        {"token": "B", "logprob": "high"},
        {"token": None, "logprob": -1.0},
        {"logprob": -1.0},
        "junk",
        {"token": "C", "logprob": True},
        {"token": "D", "logprob": float("nan")},
    ]
    s = parse_label_scores(raw, LABELS, requested=20)
    assert set(s.logprobs) == {"A"}


def test_usage_latency_and_correction_off() -> None:
    s = parse_label_scores(
        completion([("A", -0.1)]),
        LABELS,
        requested=20,
        usage=Usage(100, 1, 60),
        latency_s=0.25,
        use_logprobs=False,
    )
    assert (s.prompt_tokens, s.completion_tokens, s.cached_tokens, s.latency_s) == (
        100,
        1,
        60,
        0.25,
    )
    assert not s.logprobs_usable
    assert s.logprobs  # kept for diagnostics


def test_long_generated_text_is_capped() -> None:
    s = parse_label_scores(completion(None, content="x" * 500), LABELS, requested=20)
    assert s.text_label is not None
    assert len(s.text_label) <= 40


# ------------------------------------------------------------------ every quirk, over HTTP

PROMPT = [{"role": "user", "content": "A. hold\nB. go\nC. land\nD. orbit\nAnswer with one letter."}]


@pytest.fixture
async def fake() -> AsyncIterator[tuple[FakeProvider, ChatClient]]:
    async with FakeProvider() as fp:
        client = ChatClient(fp.base_url, "fake", deadline_s=2, retries=0)
        try:
            yield fp, client
        finally:
            await client.aclose()


async def _parse(fake: tuple[FakeProvider, ChatClient], policy: Policy, requested: int = 20) -> Any:
    fp, client = fake
    fp.policy = policy
    result = await client.chat(PROMPT, max_tokens=1, logprobs=True, top_logprobs=requested)
    return result, parse_label_scores(result.raw, LABELS, requested, usage=result.usage)


@pytest.mark.parametrize(
    ("quirk", "winner"),
    [("prefers_c", "C"), ("leading_space", "B"), ("lower_case", "B"), ("space_lower", "B"),
     ("mixed_variants", "B"), ("missing_labels", "A"), ("few_entries", "A"),
     ("bytes_null_llama", "A"), ("reasoning", "A"), ("deepseek_usage", "A")],
)  # fmt: skip
async def test_quirks_with_usable_logprobs(
    fake: tuple[FakeProvider, ChatClient], quirk: str, winner: str
) -> None:
    result, s = await _parse(fake, QUIRKS[quirk])
    assert s.logprobs_usable
    assert s.error is None
    assert choose(s, LABELS, {}, 0.0).label == winner
    assert s.text_label == winner
    assert all(lp < 0 for lp in s.logprobs.values())
    assert 0 < label_mass(s.logprobs) <= 1
    assert result.usage.prompt_tokens > 0


async def test_mixed_variants_sum_to_the_plain_label_mass(
    fake: tuple[FakeProvider, ChatClient],
) -> None:
    _, plain = await _parse(fake, Policy(prefer="B"))
    _, mixed = await _parse(fake, Policy(prefer="B", label_style="mixed"))
    assert mixed.logprobs["B"] == pytest.approx(plain.logprobs["B"])


async def test_missing_labels_are_bounded_by_the_list_floor(
    fake: tuple[FakeProvider, ChatClient],
) -> None:
    _, s = await _parse(fake, QUIRKS["missing_labels"])
    assert "D" not in s.logprobs
    assert s.extra["returned"] == 20
    assert s.omitted_bound <= min(s.logprobs.values())


async def test_floor_labels_and_padding(fake: tuple[FakeProvider, ChatClient]) -> None:
    result, s = await _parse(fake, QUIRKS["floors"])
    row = result.raw["choices"][0]["logprobs"]["content"][0]["top_logprobs"]
    assert len(row) == 20
    assert any(e["token"] == "C" and e["logprob"] == NOT_OBSERVED for e in row)
    assert "C" not in s.logprobs
    # only 8 real entries: the leftover mass bounds the omitted ones, not a -9999 floor
    assert s.omitted_bound > NOT_OBSERVED
    assert math.exp(s.omitted_bound) == pytest.approx(
        1 - sum(math.exp(e["logprob"]) for e in row if e["logprob"] > NOT_OBSERVED)
    )


async def test_fewer_entries_than_asked(fake: tuple[FakeProvider, ChatClient]) -> None:
    _, s = await _parse(fake, QUIRKS["few_entries"])
    assert s.extra["returned"] == 5
    assert s.omitted_bound > min(s.logprobs.values())  # leftover, not a floor


@pytest.mark.parametrize("quirk", ["degenerate", "degenerate_empty", "ignore_logprobs"])
async def test_unusable_quirks_fall_back_to_the_text_label(
    fake: tuple[FakeProvider, ChatClient], quirk: str
) -> None:
    _, s = await _parse(fake, QUIRKS[quirk])
    assert not s.logprobs_usable
    assert s.text_label == "B"
    assert choose(s, LABELS, {"A": 10.0}, 0.8).label == "B"


async def test_deepseek_cache_fields_are_read(fake: tuple[FakeProvider, ChatClient]) -> None:
    await _parse(fake, QUIRKS["deepseek_usage"])
    result, s = await _parse(fake, QUIRKS["deepseek_usage"])
    assert "prompt_cache_hit_tokens" in result.raw["usage"]
    assert s.cached_tokens == result.raw["usage"]["prompt_cache_hit_tokens"] > 0
