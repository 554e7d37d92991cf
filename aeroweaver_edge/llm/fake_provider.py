"""A real OpenAI-compatible HTTP server on loopback that plays providers' quirks.

Tests and the SITL-free simulator talk to it through the same ``ChatClient`` and sockets as
to a hosted provider, so retries, deadlines, content-length handling and JSON parsing are
exercised for real. It speaks ``/v1/chat/completions``, ``/v1/models``, ``/tokenize`` and
``/health`` (llama-server layout), answers from a seeded scripted ``Policy`` that can be
switched at run time (``fp.policy = ...``), and records every request.

Prompt caching is modelled like llama-server's: ``n_slots`` cache slots, each remembering
its last prompt; a request with ``id_slot`` uses that slot (wrapping, like llama.cpp's
``get_slot_by_id``), otherwise the slot sharing the longest prefix (over 10 % of the
prompt) or else the least recently used one. The shared prefix counts as cached tokens
(about 4 characters per token) in ``usage`` and, with ``llama_extras``, in ``timings``.
``POST /slots/<id>?action=save|restore`` with ``{"filename": ...}`` copies a slot's cache
through a named file, as llama-server does with ``--slot-save-path``.

Usage::

    async with FakeProvider(Policy(prefer="C")) as fp:
        client = ChatClient(fp.base_url, "fake")

    with FakeProvider(QUIRKS["hang"]).in_thread() as fp:   # sync tests
        ...
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
import math
import random
import re
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import Any, Literal

LabelStyle = Literal["plain", "space", "lower", "space_lower", "mixed"]
UsageShape = Literal["openai", "deepseek", "llama"]
Degenerate = Literal["none", "floors", "empty"]
Tokenizer = Literal["single", "split", "absent"]
JsonAnswers = Literal["schema", "garbage", "foreign_label", "refuse_schema"]

_LABEL_LINE = re.compile(r"^\s*([A-Z])\.\s", re.MULTILINE)
_DISTRACTORS = (
    "The", "I", "1", "\n", "Option", "**", "Answer", "Choose", "You", "Let", "Based", "To",
    "In", "My", "As", "It", "This", "Sure", "Here", "We", "Action", '"', "-", "(", "Hold",
    "Move", "Go", "If", "An", "So",
)  # fmt: skip
_RESIDUAL = 0.04  # mass of the rest of the vocabulary: leftover mass is never zero


@dataclass(frozen=True)
class Policy:
    """What the fake does with a chat completion. Knobs combine freely."""

    prefer: str = "A"  # the label the seeded distribution favours
    seed: int = 0
    margin: float = 3.0  # logit advantage of the preferred label
    label_style: LabelStyle = "plain"
    missing: tuple[str, ...] = ()  # labels pushed far below the top list
    floor_labels: tuple[str, ...] = ()  # labels returned inside the list at -9999
    pad_floors: bool = False  # pad a short list with -9999 entries up to the request
    max_entries: int | None = None  # return fewer entries than requested
    degenerate: Degenerate = "none"  # DeepSeek: 0 for the chosen token, -9999 / [] else
    reasoning: bool = False  # add a reasoning_content array and message.reasoning_content
    ignore_logprobs: bool = False  # answer with "logprobs": null (llamafile)
    reject_logprobs: bool = False  # 400 "logprobs is not supported" (reasoning models)
    usage: UsageShape = "openai"
    llama_extras: bool = False  # per-entry "id" and a top-level "timings" object
    bytes_null: bool = False
    content: str | None = None  # generated text; default: the top token
    finish_reason: str | None = None  # default: "length" when max_tokens <= 1 else "stop"
    status: int | None = None  # answer chat requests with this HTTP status
    status_times: int | None = None  # ... only for the first N chat requests (None: always)
    status_after: int = 0  # ... only after answering the first N (an endpoint that dies)
    retry_after: float | None = None  # Retry-After header on error statuses
    hang: bool = False  # read the request, never answer
    drip_s: float = 0.0  # send the body a few bytes at a time with this pause
    delay_s: float = 0.0  # wait before answering
    tokenizer: Tokenizer = "single"  # /tokenize: letters are one token, two, or 404
    bad_json: bool = False  # 200 with a body that is not JSON
    error_message: str | None = None  # message of the ``status`` error body
    api_key: str | None = None  # 401 unless "Authorization: Bearer <api_key>"
    models: tuple[str, ...] | None = None  # 404 "model does not exist" for any other model
    model_error_status: int = 404  # 400 for providers that say "Model Not Exist" with 400
    max_prompt_chars: int | None = None  # 400 "maximum context length" beyond this
    echo_target: bool = False  # error bodies echo the request target (query included)
    # Requests with ``response_format`` json_schema (the baselines' plans and reviews):
    # "schema": a seeded object that fits the schema (enum values favour ``prefer``);
    # "garbage": text that is no JSON; "foreign_label": every enum field gets "Z";
    # "refuse_schema": 400 naming response_format (the client must retry without it).
    json_answers: JsonAnswers = "schema"


QUIRKS: dict[str, Policy] = {
    "prefers_c": Policy(prefer="C"),
    "leading_space": Policy(prefer="B", label_style="space"),
    "lower_case": Policy(prefer="B", label_style="lower"),
    "space_lower": Policy(prefer="B", label_style="space_lower"),
    "mixed_variants": Policy(prefer="B", label_style="mixed"),
    "missing_labels": Policy(prefer="A", missing=("D", "E")),
    "floors": Policy(prefer="A", floor_labels=("C",), pad_floors=True, max_entries=8),
    "few_entries": Policy(prefer="A", max_entries=5),
    "bytes_null_llama": Policy(prefer="A", bytes_null=True, llama_extras=True, usage="llama"),
    "reasoning": Policy(prefer="A", reasoning=True, usage="deepseek"),
    "deepseek_usage": Policy(prefer="A", usage="deepseek"),
    "degenerate": Policy(prefer="B", degenerate="floors", usage="deepseek"),
    "degenerate_empty": Policy(prefer="B", degenerate="empty", usage="deepseek"),
    "ignore_logprobs": Policy(prefer="B", ignore_logprobs=True),
    "reject_logprobs": Policy(reject_logprobs=True),
    "rate_limited": Policy(status=429, retry_after=0.0),
    "server_error": Policy(status=503),
    "hang": Policy(hang=True),
    "unauthorized": Policy(api_key="sk-right-key"),
    "forbidden": Policy(status=403, error_message="Your organisation has no access to this model"),
    "wrong_model": Policy(models=("fake-model",)),
    "wrong_model_400": Policy(models=("fake-model",), model_error_status=400),
    "context_length": Policy(max_prompt_chars=200),
    "echo_target": Policy(status=404, echo_target=True),
    "drip": Policy(drip_s=0.2),
    "bad_json": Policy(bad_json=True),
}


@dataclass
class RecordedRequest:
    method: str
    path: str
    headers: dict[str, str]
    body: Any
    cached_tokens: int | None = None  # what a chat answer reported as cached


@dataclass
class _Answer:
    status: int
    body: bytes
    headers: dict[str, str] = field(default_factory=dict)


_REASONS = {200: "OK", 400: "Bad Request", 401: "Unauthorized", 403: "Forbidden",
            404: "Not Found", 405: "Method Not Allowed",
            411: "Length Required", 429: "Too Many Requests", 500: "Internal Server Error",
            502: "Bad Gateway", 503: "Service Unavailable"}  # fmt: skip


def _json(status: int, obj: object, headers: dict[str, str] | None = None) -> _Answer:
    return _Answer(status, json.dumps(obj).encode(), headers or {})


def _error(status: int, message: str, kind: str = "invalid_request_error") -> _Answer:
    return _json(status, {"error": {"message": message, "type": kind, "code": status}})


class FakeProvider:
    """The server. ``policy`` may be reassigned at any time (also from another thread)."""

    def __init__(
        self, policy: Policy | None = None, model: str = "fake-model", n_slots: int = 1
    ) -> None:
        if n_slots < 1:
            raise ValueError("n_slots must be at least 1")
        self._policy = policy or Policy()
        self.model = model
        self.n_slots = n_slots
        self._slot_prompts: dict[int, str] = {}
        self._slot_used: dict[int, int] = {}  # slot -> chat call that last used it
        self.slots_served: list[int] = []  # the cache slot of every answered chat request
        self.slot_files: dict[str, str] = {}  # saved slot caches by file name
        self.requests: list[RecordedRequest] = []
        self.chat_calls = 0
        self.connections = 0  # TCP connections accepted (keep-alive reuses one)
        self._errors_served = 0
        self._last_cached: int | None = None  # of the chat answer being built
        self._server: asyncio.Server | None = None
        self._conns: set[asyncio.Task[None]] = set()
        self._closing = asyncio.Event()
        self.port = 0

    @property
    def policy(self) -> Policy:
        return self._policy

    @policy.setter
    def policy(self, value: Policy) -> None:
        self._policy = value
        self._errors_served = 0

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}/v1"

    @property
    def root_url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def open_connections(self) -> int:
        return len(self._conns)

    def chat_bodies(self) -> list[dict[str, Any]]:
        return [r.body for r in self.requests if r.path.endswith("/chat/completions")]

    # ---------------------------------------------------------------- lifecycle

    async def start(self) -> FakeProvider:
        self._closing = asyncio.Event()
        self._server = await asyncio.start_server(self._on_connect, "127.0.0.1", 0)
        self.port = self._server.sockets[0].getsockname()[1]
        return self

    async def close(self) -> None:
        self._closing.set()
        if self._server is not None:
            self._server.close()
        for task in list(self._conns):
            task.cancel()
        await asyncio.gather(*self._conns, return_exceptions=True)
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None

    async def __aenter__(self) -> FakeProvider:
        return await self.start()

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    @contextlib.contextmanager
    def in_thread(self) -> Iterator[FakeProvider]:
        """Run the server on its own event loop in a daemon thread (for sync code)."""
        loop = asyncio.new_event_loop()
        ready = threading.Event()

        def run() -> None:
            asyncio.set_event_loop(loop)
            loop.run_until_complete(self.start())
            ready.set()
            loop.run_forever()

        thread = threading.Thread(target=run, name="fake-llm-provider", daemon=True)
        thread.start()
        ready.wait(10)
        try:
            yield self
        finally:
            asyncio.run_coroutine_threadsafe(self.close(), loop).result(10)
            loop.call_soon_threadsafe(loop.stop)
            thread.join(10)
            loop.close()

    # ---------------------------------------------------------------- HTTP/1.1

    async def _on_connect(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._conns.add(task)
        self.connections += 1
        try:
            while await self._one_request(reader, writer):
                pass
        except (ConnectionError, asyncio.IncompleteReadError, asyncio.LimitOverrunError):
            pass
        except asyncio.CancelledError:
            pass
        finally:
            self._conns.discard(task)
            writer.close()
            # Not cancelled out of here: Python 3.11's stream server logs an "Exception in
            # callback" for every client handler that ends cancelled (closed mid-request).
            with contextlib.suppress(Exception, asyncio.CancelledError):
                await writer.wait_closed()

    async def _one_request(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> bool:
        line = await reader.readline()
        if not line.strip():
            return False
        try:
            method, target, _version = line.decode("latin-1").split()
        except ValueError:
            await self._send(writer, _error(400, "bad request line"), keep=False)
            return False
        headers: dict[str, str] = {}
        while True:
            raw = await reader.readline()
            if raw in (b"\r\n", b"\n", b""):
                break
            name, _, value = raw.decode("latin-1").partition(":")
            headers[name.strip().lower()] = value.strip()
        if "chunked" in headers.get("transfer-encoding", ""):
            await self._send(writer, _error(411, "chunked bodies are not supported"), keep=False)
            return False
        length = int(headers.get("content-length", "0") or 0)
        data = await reader.readexactly(length) if length else b""
        try:
            body: Any = json.loads(data) if data else None
        except ValueError:
            body = data.decode("utf-8", "replace")
        path, _, query_text = target.partition("?")
        query = {k: v for k, _, v in (q.partition("=") for q in query_text.split("&") if q)}
        record = RecordedRequest(method, path, headers, body)
        self.requests.append(record)
        keep = headers.get("connection", "").lower() != "close"
        policy = self._policy
        if path in ("/v1/chat/completions", "/chat/completions") and method == "POST":
            if policy.hang:
                await self._until_gone(reader)
                return False
            if policy.delay_s:
                await asyncio.sleep(policy.delay_s)
            answer = self._gate(policy, headers, target, body) or self._chat(policy, body)
            record.cached_tokens = self._last_cached
            await self._send(writer, answer, keep, drip_s=policy.drip_s)
        else:
            await self._send(writer, self._route(method, path, policy, body, query), keep)
        return keep

    async def _until_gone(self, reader: asyncio.StreamReader) -> None:
        """Never answer: wait until the client hangs up or the server closes."""
        waiters = {
            asyncio.ensure_future(self._closing.wait()),
            asyncio.ensure_future(reader.read()),  # b"" at EOF
        }
        try:
            await asyncio.wait(waiters, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for waiter in waiters:
                waiter.cancel()
            await asyncio.gather(*waiters, return_exceptions=True)

    async def _send(
        self, writer: asyncio.StreamWriter, answer: _Answer, keep: bool, drip_s: float = 0.0
    ) -> None:
        head = [f"HTTP/1.1 {answer.status} {_REASONS.get(answer.status, 'Status')}"]
        hdrs = {
            "Content-Type": "application/json",
            "Content-Length": str(len(answer.body)),
            "Connection": "keep-alive" if keep else "close",
            **answer.headers,
        }
        head += [f"{k}: {v}" for k, v in hdrs.items()]
        writer.write(("\r\n".join(head) + "\r\n\r\n").encode("latin-1"))
        if drip_s > 0:
            for i in range(0, len(answer.body), 16):
                writer.write(answer.body[i : i + 16])
                await writer.drain()
                await asyncio.sleep(drip_s)
        else:
            writer.write(answer.body)
        await writer.drain()

    # ---------------------------------------------------------------- routes

    def _route(
        self, method: str, path: str, policy: Policy, body: Any, query: dict[str, str]
    ) -> _Answer:
        if path == "/health":
            return _json(200, {"status": "ok"})
        if path.startswith("/slots/") and method == "POST":
            return self._slot_action(path, query.get("action", ""), body)
        if path in ("/v1/models", "/models") and method == "GET":
            return _json(200, {"object": "list", "data": [{"id": self.model, "object": "model"}]})
        if path == "/tokenize" and method == "POST":
            if policy.tokenizer == "absent":
                return _error(404, "File Not Found")
            text = body.get("content", "") if isinstance(body, dict) else ""
            return _json(200, {"tokens": _tokenize(str(text), split=policy.tokenizer == "split")})
        return _error(404, f"no route {method} {path}")

    def _gate(
        self, policy: Policy, headers: dict[str, str], target: str, body: Any
    ) -> _Answer | None:
        """What a provider checks before it looks at the request: key, then model."""
        key = headers.get("authorization", "")
        if policy.api_key is not None and key != f"Bearer {policy.api_key}":
            self.chat_calls += 1
            return _error(401, "Incorrect API key provided", "authentication_error")
        model = body.get("model") if isinstance(body, dict) else None
        if policy.models is not None and model not in policy.models:
            self.chat_calls += 1
            if policy.model_error_status == 400:
                return _error(400, "Model Not Exist")
            return _error(
                404, f"The model `{model}` does not exist or you do not have access to it."
            )
        if policy.echo_target and policy.status is not None:
            self.chat_calls += 1
            return _error(policy.status, f"no route for POST {target}")
        return None

    def _slot_action(self, path: str, action: str, body: Any) -> _Answer:
        name = body.get("filename") if isinstance(body, dict) else None
        try:
            slot = int(path.rsplit("/", 1)[1])
        except ValueError:
            return _error(400, "bad slot id")
        if not isinstance(name, str) or not name:
            return _error(400, "filename required")
        if action == "save":
            self.slot_files[name] = self._slot_prompts.get(slot % self.n_slots, "")
            return _json(200, {"id_slot": slot, "filename": name})
        if action == "restore":
            if name not in self.slot_files:
                return _error(400, f"failed to restore slot: {name} not found")
            self._slot_prompts[slot % self.n_slots] = self.slot_files[name]
            return _json(200, {"id_slot": slot, "filename": name})
        return _error(400, f"unknown slot action {action!r}")

    def _chat(self, policy: Policy, body: Any) -> _Answer:
        self.chat_calls += 1
        self._last_cached = None
        if not isinstance(body, dict) or not isinstance(body.get("messages"), list):
            return _error(400, "messages: field required")
        if (
            policy.status is not None
            and self.chat_calls > policy.status_after
            and (policy.status_times is None or self._errors_served < policy.status_times)
        ):
            self._errors_served += 1
            extra = {} if policy.retry_after is None else {"Retry-After": f"{policy.retry_after:g}"}
            text = policy.error_message or f"scripted HTTP {policy.status}"
            return _json(policy.status, {"error": {"message": text, "code": policy.status}}, extra)
        if policy.max_prompt_chars is not None:
            chars = len(_prompt_text(body["messages"]))
            if chars > policy.max_prompt_chars:
                return _error(
                    400,
                    f"This model's maximum context length is {policy.max_prompt_chars // 4} "
                    f"tokens. However, your messages resulted in {chars // 4} tokens.",
                    "context_length_exceeded",
                )
        wants_logprobs = bool(body.get("logprobs"))
        if policy.reject_logprobs and (wants_logprobs or "top_logprobs" in body):
            return _json(
                400,
                {
                    "error": {
                        "message": "Unsupported parameter: 'logprobs' is not supported with "
                        "this model.",
                        "type": "invalid_request_error",
                        "param": "logprobs",
                        "code": "unsupported_parameter",
                    }
                },
            )
        if "top_logprobs" in body and not wants_logprobs:
            return _error(400, "Invalid top_logprobs and logprobs value")
        if policy.bad_json:
            return _Answer(200, b"<html>gateway says hello</html>")
        prompt = _prompt_text(body["messages"])
        fmt = body.get("response_format")
        if isinstance(fmt, dict) and fmt.get("type") == "json_schema":
            if policy.json_answers == "refuse_schema":
                return _error(400, "response_format json_schema is not supported by this model")
            if policy.content is None:  # scripted content wins: tests of what a model may say
                return self._json_chat(policy, body, prompt, fmt)
        requested = int(body.get("top_logprobs") or 0)
        max_tokens = int(body.get("max_tokens") or 16)
        dist = _distribution(policy, prompt)
        chosen_token, chosen_lp = dist[0]
        content = policy.content if policy.content is not None else chosen_token
        finish = policy.finish_reason or ("length" if max_tokens <= 1 else "stop")
        message: dict[str, Any] = {"role": "assistant", "content": content}
        if policy.reasoning:
            message["reasoning_content"] = "Let me think about the options."
        logprobs: dict[str, Any] | None = None
        if wants_logprobs and not policy.ignore_logprobs:
            logprobs = {
                "content": [_row(policy, chosen_token, chosen_lp, dist, requested)],
                "refusal": None,
            }
            if policy.reasoning:
                logprobs["reasoning_content"] = [
                    _entry(policy, tok, -0.05 * (i + 1), tid=900 + i, tops=[])
                    for i, tok in enumerate(("Let", " me", " think"))
                ]
        answer: dict[str, Any] = {
            "id": f"chatcmpl-fake-{self.chat_calls}",
            "object": "chat.completion",
            "created": int(time.time()),
            "model": body.get("model", self.model),
            "choices": [
                {"index": 0, "message": message, "logprobs": logprobs, "finish_reason": finish}
            ],
            "usage": self._usage(policy, prompt, body.get("id_slot")),
        }
        if policy.llama_extras:
            cache_n = self._last_cached or 0
            prompt_n = answer["usage"]["prompt_tokens"] - cache_n
            answer["timings"] = {"cache_n": cache_n, "prompt_n": prompt_n, "prompt_ms": 1.0,
                                 "prompt_per_second": 1000.0, "predicted_n": 1,
                                 "predicted_ms": 1.0, "predicted_per_second": 1000.0}  # fmt: skip
        return _json(200, answer)

    def _json_chat(
        self, policy: Policy, body: dict[str, Any], prompt: str, fmt: dict[str, Any]
    ) -> _Answer:
        """A structured-output answer: an object that fits the request's schema."""
        spec = fmt.get("json_schema")
        schema = spec.get("schema") if isinstance(spec, dict) else None
        digest = hashlib.sha256(f"{policy.seed}\x00json\x00{prompt}".encode()).digest()
        rng = random.Random(int.from_bytes(digest[:8], "big"))
        if policy.json_answers == "garbage":
            content = "Sure! Here is my plan: uav0 goes first."
        else:
            value = _from_schema(schema if isinstance(schema, dict) else {}, rng, policy)
            content = json.dumps(value, separators=(", ", ": "))
        usage = self._usage(policy, prompt, body.get("id_slot"))
        usage["completion_tokens"] = max(1, len(content) // 4)
        usage["total_tokens"] = usage["prompt_tokens"] + usage["completion_tokens"]
        answer = {
            "id": f"chatcmpl-fake-{self.chat_calls}",
            "object": "chat.completion",
            "created": int(time.time()),
            "model": body.get("model", self.model),
            "choices": [
                {
                    "index": 0,
                    "message": {"role": "assistant", "content": content},
                    "logprobs": None,
                    "finish_reason": "stop",
                }
            ],
            "usage": usage,
        }
        return _json(200, answer)

    def _slot(self, prompt: str, id_slot: object) -> tuple[int, int]:
        """The cache slot a prompt lands in and the characters it shares with that slot."""
        if isinstance(id_slot, int) and not isinstance(id_slot, bool) and id_slot >= 0:
            slot = id_slot % self.n_slots
            return slot, _common_prefix(prompt, self._slot_prompts.get(slot, ""))
        best, best_common = None, 0
        for slot, cached in sorted(self._slot_prompts.items()):
            common = _common_prefix(prompt, cached)
            if common > best_common and common > 0.1 * len(prompt):
                best, best_common = slot, common
        if best is not None:
            return best, best_common
        lru = min(range(self.n_slots), key=lambda s: (self._slot_used.get(s, -1), s))
        return lru, _common_prefix(prompt, self._slot_prompts.get(lru, ""))

    def _usage(self, policy: Policy, prompt: str, id_slot: object = None) -> dict[str, Any]:
        """~4 characters per token; the prefix shared with the slot's last prompt is cached."""
        prompt_tokens = max(1, len(prompt) // 4)
        slot, common = self._slot(prompt, id_slot)
        self._slot_prompts[slot] = prompt
        self._slot_used[slot] = self.chat_calls
        self.slots_served.append(slot)
        cached = self._last_cached = min(prompt_tokens, common // 4)
        usage: dict[str, Any] = {
            "prompt_tokens": prompt_tokens,
            "completion_tokens": 1,
            "total_tokens": prompt_tokens + 1,
        }
        if policy.usage == "deepseek":
            usage["prompt_cache_hit_tokens"] = cached
            usage["prompt_cache_miss_tokens"] = prompt_tokens - cached
            usage["completion_tokens_details"] = {"reasoning_tokens": 3 if policy.reasoning else 0}
        else:
            usage["prompt_tokens_details"] = {"cached_tokens": cached}
            if policy.usage == "openai":
                usage["completion_tokens_details"] = {
                    "reasoning_tokens": 0,
                    "accepted_prediction_tokens": 0,
                    "rejected_prediction_tokens": 0,
                }
        return usage


# -------------------------------------------------------------------- the scripted model


def _from_schema(schema: dict[str, Any], rng: random.Random, policy: Policy) -> Any:
    """A value that fits ``schema`` (objects, enums, booleans, strings, numbers)."""
    if "enum" in schema and isinstance(schema["enum"], list) and schema["enum"]:
        if policy.json_answers == "foreign_label":
            return "Z"
        options = schema["enum"]
        if policy.prefer in options and rng.random() < 0.7:
            return policy.prefer
        return rng.choice(options)
    kind = schema.get("type")
    if kind == "object":
        props = schema.get("properties")
        props = props if isinstance(props, dict) else {}
        return {
            k: _from_schema(v if isinstance(v, dict) else {}, rng, policy) for k, v in props.items()
        }
    if kind == "boolean":
        return rng.random() < 0.7
    if kind in ("integer", "number"):
        return rng.randint(0, 3)
    if kind == "array":
        return []
    return "ok"


def _common_prefix(a: str, b: str) -> int:
    n = 0
    for x, y in zip(a, b, strict=False):
        if x != y:
            break
        n += 1
    return n


def _prompt_text(messages: list[Any]) -> str:
    parts = []
    for m in messages:
        if isinstance(m, dict) and isinstance(m.get("content"), str):
            parts.append(f"[{m.get('role', '')}]\n{m['content']}")
    return "\n".join(parts)


def _labels_in(prompt: str) -> list[str]:
    """Candidate labels listed as ``A. ...`` lines; A–H when the prompt has none."""
    found = list(dict.fromkeys(_LABEL_LINE.findall(prompt)))
    return found or list("ABCDEFGH")


def _spell(label: str, style: LabelStyle) -> str:
    return {"plain": label, "space": f" {label}", "lower": label.lower(),
            "space_lower": f" {label.lower()}", "mixed": label}[style]  # fmt: skip


def _distribution(policy: Policy, prompt: str) -> list[tuple[str, float]]:
    """Seeded, prompt-deterministic next-token distribution, best first (log-probs)."""
    digest = hashlib.sha256(f"{policy.seed}\x00{prompt}".encode()).digest()
    rng = random.Random(int.from_bytes(digest[:8], "big"))
    labels = _labels_in(prompt)
    logits: dict[str, float] = {}
    for label in labels:
        if label in policy.missing:
            value = -12.0
        elif label == policy.prefer:
            value = policy.margin + rng.gauss(0.0, 0.3)
        else:
            value = rng.gauss(0.0, 1.0)
        if policy.label_style == "mixed":  # split the label's mass over two spellings
            logits[label] = value + math.log(0.7)
            logits[f" {label}"] = value + math.log(0.3)
        else:
            logits[_spell(label, policy.label_style)] = value
    for token in _DISTRACTORS:
        logits.setdefault(token, rng.gauss(-3.0, 1.2))
    top = max(logits.values())
    z = sum(math.exp(v - top) for v in logits.values())
    scale = math.log(1.0 - _RESIDUAL)
    dist = [(tok, v - top - math.log(z) + scale) for tok, v in logits.items()]
    dist.sort(key=lambda item: -item[1])
    return dist


def _entry(
    policy: Policy, token: str, logprob: float, tid: int, tops: list[dict[str, Any]] | None = None
) -> dict[str, Any]:
    entry: dict[str, Any] = {
        "token": token,
        "logprob": logprob,
        "bytes": None if policy.bytes_null else list(token.encode()),
    }
    if policy.llama_extras:
        entry["id"] = tid
    if tops is not None:
        entry["top_logprobs"] = tops
    return entry


def _token_id(token: str) -> int:
    return int.from_bytes(hashlib.sha256(token.encode()).digest()[:2], "big")


def _row(
    policy: Policy,
    chosen: str,
    chosen_lp: float,
    dist: list[tuple[str, float]],
    requested: int,
) -> dict[str, Any]:
    if policy.degenerate != "none":
        tops: list[dict[str, Any]] = []
        if policy.degenerate == "floors":
            tops = [_entry(policy, chosen, 0.0, _token_id(chosen))] + [
                _entry(policy, tok, -9999.0, _token_id(tok)) for tok, _ in dist[1:requested]
            ]
        return _entry(policy, chosen, 0.0, _token_id(chosen), tops)
    count = requested if policy.max_entries is None else min(requested, policy.max_entries)
    floored = {_spell(lb, policy.label_style) for lb in policy.floor_labels}
    shown = [(tok, lp) for tok, lp in dist if tok not in floored][:count]
    items = [_entry(policy, tok, lp, _token_id(tok)) for tok, lp in shown]
    for tok in sorted(floored):  # a top token the provider could not score
        items.append(_entry(policy, tok, -9999.0, _token_id(tok)))
    if policy.pad_floors:
        used = {t for t, _ in shown} | floored
        pads = [tok for tok in _DISTRACTORS if tok not in used]
        for tok in pads[: max(0, requested - len(items))]:
            items.append(_entry(policy, tok, -9999.0, _token_id(tok)))
    return _entry(policy, chosen, chosen_lp, _token_id(chosen), items)


def _tokenize(text: str, split: bool) -> list[int]:
    """Letters are single tokens (ids 49..74 like SmolLM2's A..Z) unless ``split``;
    other words get one id each."""
    out: list[int] = []
    for word in re.findall(r"\s*\S+", text):
        stripped = word.strip()
        if len(stripped) == 1 and stripped.isascii() and stripped.isalpha():
            base = 49 + ord(stripped.upper()) - ord("A") + (0 if word == stripped else 281)
            out.extend([base, 0] if split else [base])
        else:
            out.append(_token_id(word))
    return out


def with_policy(policy: Policy, **changes: Any) -> Policy:
    """A copy of ``policy`` with some knobs changed (keeps test code short)."""
    return replace(policy, **changes)
