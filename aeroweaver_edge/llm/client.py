"""One OpenAI-compatible chat client for every LLM call the swarm makes (DESIGN §8).

Budgets are explicit because a decision round has a deadline: the whole call (connect,
retries, back-off, body) runs under one ``asyncio.timeout``; retries happen only for
transient failures (429, 5xx, connection errors) and never sleep past the deadline; a
circuit breaker stops hammering an endpoint that keeps failing so rounds hold quickly.
Every call, failed or not, is journaled in a ``UsageLedger`` so token and latency totals per
agent, role and episode are plain sums.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import random
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal
from urllib.parse import urlsplit, urlunsplit

import httpx

from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.runtime.redact import (
    install_log_redaction,
    redact_url,
    register_secrets,
    scrub,
    url_secrets,
)

log = logging.getLogger(__name__)
install_log_redaction()  # httpx logs every request URL at INFO (-v): never its secrets

_EXCERPT = 240
MAX_BODY_BYTES = 4 * 1024 * 1024
"""Largest answer body read: a chat completion with 20 top logprobs per token and a few
hundred tokens is tens of KB; a body beyond this is refused as a bad response while it
streams in, never held whole in memory."""
MAX_ERROR_BYTES = 64 * 1024
"""Of an error answer only the start is read (its excerpt goes into the message)."""


# --------------------------------------------------------------------------- errors


class LLMError(Exception):
    """Any failure of an LLM call. The message names the cause and the endpoint."""

    def __init__(self, message: str, endpoint: str = "") -> None:
        super().__init__(message)
        self.endpoint = endpoint
        self.attempts = 0  # requests this call sent before it failed


class LLMTimeout(LLMError):
    """The call did not complete within its deadline."""


class LLMUnreachable(LLMError):
    """No connection could be made (refused, DNS, connect timeout)."""


class LLMHTTPError(LLMError):
    """The endpoint answered with a non-2xx status."""

    def __init__(self, message: str, endpoint: str, status: int, body: str) -> None:
        super().__init__(message, endpoint)
        self.status = status
        self.body = body


class LLMBreakerOpen(LLMError):
    """The circuit breaker is open: the call was refused without touching the network."""


class LLMBadResponse(LLMError):
    """The endpoint answered 2xx but the body is not a usable chat completion."""


class LLMConfigError(LLMError):
    """The client cannot be built as configured (e.g. the API-key variable is unset)."""

    def explain(self) -> tuple[int, str]:
        return 2, f"{self}; export it, or drop --api-key-env / llm.api_key_env"


def _excerpt(text: str, limit: int = _EXCERPT) -> str:
    flat = " ".join(text.split())
    return flat if len(flat) <= limit else flat[: limit - 1] + "…"


def _endpoint_name(base_url: str) -> str:
    """The URL with credentials masked, safe to print in errors and logs."""
    return redact_url(base_url).rstrip("/")


# --------------------------------------------------------------------------- usage


def _int(value: object) -> int:
    return value if isinstance(value, int) and not isinstance(value, bool) and value > 0 else 0


@dataclass(frozen=True)
class Usage:
    """Token counts of one call. ``cached_tokens`` is part of ``prompt_tokens``."""

    prompt_tokens: int = 0
    completion_tokens: int = 0
    cached_tokens: int = 0
    reasoning_tokens: int = 0

    @property
    def total_tokens(self) -> int:
        return self.prompt_tokens + self.completion_tokens

    @classmethod
    def from_response(cls, raw: Mapping[str, Any]) -> Usage:
        """Read OpenAI, DeepSeek and llama-server usage shapes.

        Cached prompt tokens come from ``prompt_tokens_details.cached_tokens`` (OpenAI,
        llama-server) or ``prompt_cache_hit_tokens`` (DeepSeek); llama-server's
        ``timings.cache_n`` is the last resort. The largest reported value wins.
        """
        usage = raw.get("usage")
        usage = usage if isinstance(usage, Mapping) else {}
        ptd = usage.get("prompt_tokens_details")
        ctd = usage.get("completion_tokens_details")
        timings = raw.get("timings")
        cached = max(
            _int(ptd.get("cached_tokens")) if isinstance(ptd, Mapping) else 0,
            _int(usage.get("prompt_cache_hit_tokens")),
            _int(timings.get("cache_n")) if isinstance(timings, Mapping) else 0,
        )
        prompt = _int(usage.get("prompt_tokens"))
        return cls(
            prompt_tokens=prompt,
            completion_tokens=_int(usage.get("completion_tokens")),
            cached_tokens=min(cached, prompt) if prompt else cached,
            reasoning_tokens=_int(ctd.get("reasoning_tokens")) if isinstance(ctd, Mapping) else 0,
        )


@dataclass(frozen=True)
class CallTag:
    """Who made a call, for per-agent / per-role / per-episode sums."""

    agent: str = ""
    role: str = ""
    episode: int | None = None
    round: int | None = None
    purpose: str = "chat"


@dataclass(frozen=True)
class LedgerEntry:
    tag: CallTag
    endpoint: str
    model: str
    ok: bool
    usage: Usage
    latency_s: float
    attempts: int
    error: str | None = None  # error class name, e.g. "LLMTimeout"
    at: float = field(default_factory=time.time)


@dataclass
class UsageTotals:
    calls: int = 0
    errors: int = 0
    prompt_tokens: int = 0
    completion_tokens: int = 0
    cached_tokens: int = 0
    latency_s: float = 0.0

    def add(self, entry: LedgerEntry) -> None:
        self.calls += 1
        self.errors += 0 if entry.ok else 1
        self.prompt_tokens += entry.usage.prompt_tokens
        self.completion_tokens += entry.usage.completion_tokens
        self.cached_tokens += entry.usage.cached_tokens
        self.latency_s += entry.latency_s

    @property
    def total_tokens(self) -> int:
        return self.prompt_tokens + self.completion_tokens

    @property
    def mean_latency_s(self) -> float:
        return self.latency_s / self.calls if self.calls else 0.0


class UsageLedger:
    """Journal of every call plus running sums per agent, role and episode.

    Sums are kept incrementally so they stay exact even when the journal (bounded, for
    long-running field daemons) drops its oldest entries.
    """

    def __init__(self, max_journal: int = 100_000) -> None:
        self._journal: deque[LedgerEntry] = deque(maxlen=max_journal)
        self.total = UsageTotals()
        self._by_agent: dict[str, UsageTotals] = {}
        self._by_role: dict[str, UsageTotals] = {}
        self._by_episode: dict[int | None, UsageTotals] = {}

    def record(self, entry: LedgerEntry) -> None:
        self._journal.append(entry)
        self.total.add(entry)
        self._by_agent.setdefault(entry.tag.agent, UsageTotals()).add(entry)
        self._by_role.setdefault(entry.tag.role, UsageTotals()).add(entry)
        self._by_episode.setdefault(entry.tag.episode, UsageTotals()).add(entry)

    @property
    def journal(self) -> list[LedgerEntry]:
        return list(self._journal)

    def by_agent(self) -> dict[str, UsageTotals]:
        return dict(self._by_agent)

    def by_role(self) -> dict[str, UsageTotals]:
        return dict(self._by_role)

    def by_episode(self) -> dict[int | None, UsageTotals]:
        return dict(self._by_episode)

    def totals_for(
        self, *, agent: str | None = None, role: str | None = None, episode: int | None = None
    ) -> UsageTotals:
        """Sums over the (retained) journal for any combination of filters."""
        out = UsageTotals()
        for entry in self._journal:
            if agent is not None and entry.tag.agent != agent:
                continue
            if role is not None and entry.tag.role != role:
                continue
            if episode is not None and entry.tag.episode != episode:
                continue
            out.add(entry)
        return out


# --------------------------------------------------------------------------- breaker

BreakerState = Literal["closed", "open", "half_open"]


class CircuitBreaker:
    """Opens after ``failures`` consecutive failed calls; after ``reset_s`` one trial call
    is let through (half-open). Its success closes the breaker, its failure re-opens it.
    While open (or while the trial is in flight) calls fail fast."""

    def __init__(
        self, failures: int, reset_s: float, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.threshold = failures
        self.reset_s = reset_s
        self._clock = clock
        self._consecutive = 0
        self._opened_at: float | None = None
        self._trial_in_flight = False
        self.last_error = ""

    @property
    def state(self) -> BreakerState:
        if self._opened_at is None:
            return "closed"
        if self._trial_in_flight or self._clock() - self._opened_at >= self.reset_s:
            return "half_open"
        return "open"

    def before_call(self, endpoint: str) -> None:
        """Raise ``LLMBreakerOpen`` unless a call may go out now."""
        if self._opened_at is None:
            return
        waited = self._clock() - self._opened_at
        if waited >= self.reset_s and not self._trial_in_flight:
            self._trial_in_flight = True  # this caller is the half-open probe
            return
        retry_in = max(0.0, self.reset_s - waited)
        raise LLMBreakerOpen(
            f"circuit breaker open for {endpoint} after {self._consecutive} consecutive "
            f"failures (last: {self.last_error}); failing fast, next trial in {retry_in:.1f} s",
            endpoint,
        )

    def success(self) -> None:
        self._consecutive = 0
        self._opened_at = None
        self._trial_in_flight = False

    def failure(self, error: str) -> None:
        self._consecutive += 1
        self.last_error = error
        if self._trial_in_flight or self._consecutive >= self.threshold:
            self._opened_at = self._clock()
        self._trial_in_flight = False

    def release(self) -> None:
        """The trial ended without a verdict (e.g. cancelled): let the next caller try."""
        self._trial_in_flight = False


# --------------------------------------------------------------------------- client


@dataclass(frozen=True)
class ChatResult:
    raw: dict[str, Any]
    usage: Usage
    latency_s: float
    attempts: int
    endpoint: str
    model: str


class _Retryable(Exception):
    def __init__(self, error: LLMError, retry_after: float | None = None) -> None:
        super().__init__(str(error))
        self.error = error
        self.retry_after = retry_after


def _parse_json(data: bytes) -> Any:
    """The JSON value of ``data``; ``None`` when it is not JSON, including a document nested
    so deep that the decoder gives up (``RecursionError``): a bad answer, not a crash."""
    try:
        return json.loads(data)
    except (ValueError, RecursionError):
        return None


def _retry_after(headers: httpx.Headers) -> float | None:
    value = headers.get("retry-after")
    try:
        return max(0.0, float(value)) if value is not None else None
    except ValueError:
        return None


class ChatClient:
    """Async chat-completions client for one endpoint and model.

    ``extra_body`` is merged into every request body last (as in the OpenAI SDK), so the
    operator's config can add provider switches such as DeepSeek's
    ``thinking: {"type": "disabled"}`` or override a default.
    """

    def __init__(
        self,
        base_url: str,
        model: str,
        *,
        api_key_env: str | None = None,
        extra_body: Mapping[str, Any] | None = None,
        deadline_s: float = 20.0,
        connect_timeout_s: float = 2.0,
        retries: int = 1,
        breaker_failures: int = 3,
        breaker_reset_s: float = 10.0,
        backoff_s: float = 0.25,
        backoff_cap_s: float = 2.0,
        ledger: UsageLedger | None = None,
        transport: httpx.AsyncBaseTransport | None = None,
        clock: Callable[[], float] = time.monotonic,
        rng: random.Random | None = None,
    ) -> None:
        self.base_url = base_url.rstrip("/")
        self.endpoint = _endpoint_name(self.base_url)
        self._secrets = url_secrets(self.base_url)
        # A query in the base URL (``?api-version=...``, a proxy's ``?api_key=...``) goes on
        # every request as parameters: httpx would glue the request path after it.
        parts = urlsplit(self.base_url)
        self._query = httpx.QueryParams(parts.query)
        http_base = urlunsplit((parts.scheme, parts.netloc, parts.path, "", ""))
        self._http_base = http_base
        self.requests_sent = 0  # HTTP requests to /chat/completions, answered or not
        self.model = model
        self.extra_body = dict(extra_body or {})
        self.deadline_s = deadline_s
        self.connect_timeout_s = connect_timeout_s
        self.retries = retries
        self.backoff_s = backoff_s
        self.backoff_cap_s = backoff_cap_s
        self.ledger = ledger if ledger is not None else UsageLedger()
        self.breaker = CircuitBreaker(breaker_failures, breaker_reset_s, clock)
        self._rng = rng or random.Random()
        headers = {"Content-Type": "application/json"}
        if api_key_env:
            key = os.environ.get(api_key_env)
            if not key:
                raise LLMConfigError(
                    f"environment variable {api_key_env} (API key for {self.endpoint}) is "
                    "not set or empty",
                    self.endpoint,
                )
            headers["Authorization"] = f"Bearer {key}"
            self._secrets.append(key)
        register_secrets(self._secrets)  # the log filter masks them in any library's lines
        self._http = httpx.AsyncClient(
            base_url=http_base,
            headers=headers,
            timeout=self._timeout(deadline_s),
            transport=transport,
        )

    def _timeout(self, deadline: float) -> httpx.Timeout:
        """httpx's own timeouts sit just past the asyncio deadline, which bounds the whole
        call, so that a hang always surfaces as our ``LLMTimeout``."""
        return httpx.Timeout(deadline + 1.0, connect=min(self.connect_timeout_s, deadline))

    @classmethod
    def from_config(
        cls,
        cfg: LLMConfig,
        *,
        base_url: str | None = None,
        ledger: UsageLedger | None = None,
        transport: httpx.AsyncBaseTransport | None = None,
    ) -> ChatClient:
        """Build from ``LLMConfig``; ``base_url`` overrides it (the embedded server's URL)."""
        url = base_url or cfg.base_url
        if not url:
            raise LLMConfigError("no base_url: start the embedded server or set llm.base_url")
        return cls(
            url,
            cfg.model,
            api_key_env=cfg.api_key_env,
            extra_body=cfg.extra_body,
            deadline_s=cfg.deadline_s,
            connect_timeout_s=cfg.connect_timeout_s,
            retries=cfg.retries,
            breaker_failures=cfg.breaker_failures,
            breaker_reset_s=cfg.breaker_reset_s,
            ledger=ledger,
            transport=transport,
        )

    def __repr__(self) -> str:  # never shows headers (API key)
        return f"ChatClient({self.endpoint!r}, model={self.model!r})"

    async def __aenter__(self) -> ChatClient:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.aclose()

    async def aclose(self) -> None:
        await self._http.aclose()

    # ---------------------------------------------------------------- chat

    async def chat(
        self,
        messages: Sequence[Mapping[str, Any]],
        *,
        tag: CallTag | None = None,
        deadline_s: float | None = None,
        **params: Any,
    ) -> ChatResult:
        """One non-streaming chat completion, or a typed ``LLMError``."""
        body: dict[str, Any] = {"model": self.model, "messages": list(messages), "stream": False}
        body.update(params)
        body.update(self.extra_body)
        deadline = self.deadline_s if deadline_s is None else deadline_s
        tag = tag or CallTag()
        started = time.perf_counter()
        attempts = 0
        try:
            self.breaker.before_call(self.endpoint)
        except LLMBreakerOpen as exc:
            self._journal(tag, False, Usage(), 0.0, 0, exc)
            raise
        verdict = False
        try:
            result, attempts = await self._attempts(body, deadline, started)
            verdict = True
            self.breaker.success()
            self._journal(tag, True, result.usage, result.latency_s, attempts, None)
            return result
        except LLMError as exc:
            verdict = True
            attempts = exc.attempts
            if isinstance(exc, LLMHTTPError) and exc.status != 429 and exc.status < 500:
                self.breaker.success()  # the endpoint is alive; the request was wrong
            else:
                self.breaker.failure(f"{type(exc).__name__}: {_excerpt(str(exc), 120)}")
            self._journal(tag, False, Usage(), time.perf_counter() - started, attempts, exc)
            raise
        finally:
            if not verdict:  # cancelled from outside: no verdict on the endpoint
                self.breaker.release()

    async def _attempts(
        self, body: dict[str, Any], deadline: float, started: float
    ) -> tuple[ChatResult, int]:
        attempts = 0
        try:
            async with asyncio.timeout(deadline):
                while True:
                    attempts += 1
                    try:
                        raw = await self._post_once(body, deadline)
                    except LLMError as exc:
                        exc.attempts = attempts
                        raise
                    except _Retryable as retry:
                        retry.error.attempts = attempts
                        if attempts > self.retries:
                            raise retry.error from None
                        delay = self._rng.uniform(
                            0.0, min(self.backoff_cap_s, self.backoff_s * 2 ** (attempts - 1))
                        )
                        if retry.retry_after is not None:
                            delay = max(delay, retry.retry_after)
                        remaining = deadline - (time.perf_counter() - started)
                        if delay >= remaining:  # a retry could not finish in time
                            raise retry.error from None
                        log.debug("retrying %s in %.2f s: %s", self.endpoint, delay, retry.error)
                        await asyncio.sleep(delay)
                        continue
                    latency = time.perf_counter() - started
                    usage = Usage.from_response(raw)
                    return ChatResult(
                        raw, usage, latency, attempts, self.endpoint, self.model
                    ), attempts
        except TimeoutError:
            timeout = LLMTimeout(
                f"no answer from {self.endpoint} within the {deadline:g} s deadline "
                f"(attempt {attempts} of {self.retries + 1})",
                self.endpoint,
            )
            timeout.attempts = attempts
            raise timeout from None

    def _scrub(self, text: str) -> str:
        return scrub(text, self._secrets)

    async def _post_once(self, body: dict[str, Any], deadline: float) -> dict[str, Any]:
        self.requests_sent += 1
        try:
            status, headers, data, whole = await self._post(
                "/chat/completions", body, self._timeout(deadline)
            )
        except (httpx.ConnectError, httpx.ConnectTimeout) as exc:
            raise _Retryable(
                LLMUnreachable(
                    f"cannot connect to {self.endpoint}: "
                    f"{type(exc).__name__}: {self._scrub(str(exc))}",
                    self.endpoint,
                )
            ) from None
        except httpx.TransportError as exc:  # reset mid-answer, protocol error, read timeout
            raise LLMBadResponse(
                f"transport error talking to {self.endpoint}: "
                f"{type(exc).__name__}: {self._scrub(str(exc))}",
                self.endpoint,
            ) from None
        text = data.decode("utf-8", errors="replace")
        if status >= 300:
            excerpt = self._scrub(_excerpt(text))
            err = LLMHTTPError(
                f"HTTP {status} from {self.endpoint}: {excerpt}", self.endpoint, status, excerpt
            )
            if status == 429 or status >= 500:
                raise _Retryable(err, _retry_after(headers))
            raise err
        if not whole:
            raise LLMBadResponse(
                f"answer from {self.endpoint} is over {MAX_BODY_BYTES // 1024 // 1024} MB "
                "(no chat completion is that large); not read further",
                self.endpoint,
            )
        raw = _parse_json(data)
        if raw is None:
            raise LLMBadResponse(
                f"non-JSON (or absurdly nested JSON) answer from {self.endpoint}: "
                f"{self._scrub(_excerpt(text, 120))}",
                self.endpoint,
            )
        choices = raw.get("choices") if isinstance(raw, dict) else None
        if not isinstance(choices, list) or not choices or not isinstance(choices[0], dict):
            raise LLMBadResponse(
                f"answer from {self.endpoint} has no choices: {self._scrub(_excerpt(text, 120))}",
                self.endpoint,
            )
        out: dict[str, Any] = raw
        return out

    async def _post(
        self, url: str, body: dict[str, Any], http_timeout: httpx.Timeout | None = None
    ) -> tuple[int, httpx.Headers, bytes, bool]:
        """POST ``body``; (status, headers, the body's first bytes, whether that is all of
        it). The body streams in and reading stops at the cap (``MAX_BODY_BYTES``, or
        ``MAX_ERROR_BYTES`` for an error status), so a huge answer costs no memory."""
        request = self._http.build_request(
            "POST", url, json=body, params=self._query or None,
            timeout=http_timeout if http_timeout is not None else self._http.timeout,
        )  # fmt: skip
        response = await self._http.send(request, stream=True)
        try:
            cap = MAX_ERROR_BYTES if response.status_code >= 300 else MAX_BODY_BYTES
            declared = response.headers.get("content-length", "")
            if declared.isdigit() and int(declared) > cap:
                return response.status_code, response.headers, b"", False
            chunks: list[bytes] = []
            size = 0
            async for chunk in response.aiter_bytes():  # decoded: a gzip bomb counts in full
                chunks.append(chunk)
                size += len(chunk)
                if size > cap:
                    return response.status_code, response.headers, b"".join(chunks)[:cap], False
            return response.status_code, response.headers, b"".join(chunks), True
        finally:
            await response.aclose()

    def _journal(
        self,
        tag: CallTag,
        ok: bool,
        usage: Usage,
        latency: float,
        attempts: int,
        error: LLMError | None,
    ) -> None:
        self.ledger.record(
            LedgerEntry(
                tag=tag,
                endpoint=self.endpoint,
                model=self.model,
                ok=ok,
                usage=usage,
                latency_s=latency,
                attempts=attempts,
                error=type(error).__name__ if error else None,
            )
        )

    # ---------------------------------------------------------------- tokenize

    @property
    def server_root(self) -> str:
        """The server URL without a trailing ``/v1`` (llama-server's extra endpoints live there)."""
        base = self._http_base
        return base[:-3] if base.endswith("/v1") else base

    async def tokenize(self, text: str) -> list[int] | None:
        """Token ids of ``text`` via llama-server's ``/tokenize``; ``None`` when the endpoint
        has no such route (any 4xx: hosted providers answer 404, 401 or 405).

        Used to check that labels are single tokens. No retries and no breaker: it is a
        start-up check, not part of a round.
        """
        url = f"{self.server_root}/tokenize"
        try:
            async with asyncio.timeout(self.deadline_s):
                status, _headers, data, whole = await self._post(
                    url, {"content": text, "add_special": False}
                )
        except TimeoutError:
            raise LLMTimeout(f"/tokenize at {self.endpoint} timed out", self.endpoint) from None
        except httpx.TransportError as exc:
            raise LLMUnreachable(
                f"cannot reach /tokenize at {self.endpoint}: {type(exc).__name__}", self.endpoint
            ) from None
        if 400 <= status < 500:
            return None
        if status >= 300:
            raise LLMHTTPError(
                f"HTTP {status} from /tokenize at {self.endpoint}",
                self.endpoint,
                status,
                self._scrub(_excerpt(data.decode("utf-8", errors="replace"))),
            )
        parsed = _parse_json(data) if whole else None
        tokens = parsed.get("tokens") if isinstance(parsed, dict) else None
        if not isinstance(tokens, list):
            raise LLMBadResponse(f"/tokenize at {self.endpoint} gave no token list", self.endpoint)
        out: list[int] = []
        for tok in tokens:  # plain ids, or {"id", "piece"} when pieces were requested
            if isinstance(tok, dict):
                tok = tok.get("id")
            if not isinstance(tok, int):
                raise LLMBadResponse(
                    f"/tokenize at {self.endpoint}: bad token {tok!r}", self.endpoint
                )
            out.append(tok)
        return out
