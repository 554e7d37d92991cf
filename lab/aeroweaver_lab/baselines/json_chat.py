"""Chat calls whose answer must be one JSON object of a given schema.

The request carries OpenAI's ``response_format: {"type": "json_schema", ...}`` (llama.cpp's
server turns it into a grammar, so even a 135M model answers well-formed JSON). An endpoint
that refuses the parameter (HTTP 400 naming it) is asked again once without it, and never
again with it; the prompt itself always spells out the format, so that works too. The
answer is still validated by the caller: a schema is a request, not a guarantee.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from aeroweaver_edge.llm.client import CallTag, ChatClient, ChatResult, LLMError, LLMHTTPError

log = logging.getLogger(__name__)


@dataclass
class JsonMode:
    """Whether this endpoint accepts ``response_format`` json_schema (learned once)."""

    schema_ok: bool = True


@dataclass(frozen=True)
class JsonAnswer:
    """One call's outcome: the parsed object (None: no JSON object in the answer), the raw
    text, usage, latency, and the error when the call itself failed."""

    value: dict[str, Any] | None
    text: str
    prompt_tokens: int = 0
    cached_tokens: int = 0
    completion_tokens: int = 0
    latency_s: float = 0.0
    requests: int = 0
    error: str | None = None


def response_format(name: str, schema: Mapping[str, Any]) -> dict[str, Any]:
    return {
        "type": "json_schema",
        "json_schema": {"name": name, "strict": True, "schema": dict(schema)},
    }


def extract_object(text: str) -> dict[str, Any] | None:
    """The first JSON object in ``text`` (code fences and chatter around it tolerated)."""
    start = text.find("{")
    while start != -1:
        try:
            value, _end = json.JSONDecoder().raw_decode(text, start)
        except ValueError:
            start = text.find("{", start + 1)
            continue
        return value if isinstance(value, dict) else None
    return None


def _content(result: ChatResult) -> str:
    try:
        choice = result.raw["choices"][0]
        content = choice["message"].get("content")
    except (KeyError, IndexError, TypeError, AttributeError):
        return ""
    return content if isinstance(content, str) else ""


def _schema_refused(exc: LLMError) -> bool:
    if not isinstance(exc, LLMHTTPError) or exc.status not in (400, 422):
        return False
    text = f"{exc} {exc.body}".lower()
    return any(w in text for w in ("response_format", "json_schema", "schema", "grammar"))


async def json_chat(
    client: ChatClient,
    messages: Sequence[Mapping[str, str]],
    schema: Mapping[str, Any],
    *,
    name: str,
    max_tokens: int,
    tag: CallTag,
    mode: JsonMode,
    slot: int | None = None,
) -> JsonAnswer:
    """One schema'd call (never raises an ``LLMError``: it comes back in ``error``)."""
    params: dict[str, Any] = {"max_tokens": max_tokens, "temperature": 0.0}
    if slot is not None:
        params["id_slot"] = slot
    sent_before = client.requests_sent
    try:
        if mode.schema_ok:
            try:
                result = await client.chat(
                    messages, tag=tag, response_format=response_format(name, schema), **params
                )
            except LLMError as exc:
                if not _schema_refused(exc):
                    raise
                mode.schema_ok = False
                log.warning("%s refuses json_schema output; asking without it", exc.endpoint)
                result = await client.chat(messages, tag=tag, **params)
        else:
            result = await client.chat(messages, tag=tag, **params)
    except LLMError as exc:
        return JsonAnswer(
            None,
            "",
            requests=client.requests_sent - sent_before,
            error=f"{type(exc).__name__}: {exc}",
        )
    text = _content(result)
    u = result.usage
    return JsonAnswer(
        extract_object(text),
        text,
        prompt_tokens=u.prompt_tokens,
        cached_tokens=u.cached_tokens,
        completion_tokens=u.completion_tokens,
        latency_s=result.latency_s,
        requests=client.requests_sent - sent_before,
    )


__all__ = ["JsonAnswer", "JsonMode", "extract_object", "json_chat", "response_format"]
