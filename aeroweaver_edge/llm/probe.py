"""Start-up endpoint probe: can this endpoint's first-token logprobs drive the selector?

One 1-token request with logprobs, classified by what the endpoint says. A verdict on
logprobs (the selector acts on it for the rest of the run):

* ``ok`` — a real distribution with enough mass on the labels: experience correction on;
* ``rejected`` — the endpoint refuses logprobs (a 400/422 that goes away when the same
  request is sent again without logprob parameters, and that either names logprobs or
  repeats: one unexplained 400 may be transient, and a verdict holds for the whole run) or
  silently drops them;
* ``degenerate`` — only 0 / -9999 values or an empty top list (an argmax, not a distribution);
* ``low_label_mass`` — labels get too little of the mass (e.g. a base model).

No verdict, the endpoint is unusable as configured (each names its fix):

* ``auth`` (401/403), ``not_found`` (404: wrong base URL or model), ``bad_request`` (a
  400/422 that stays without logprobs: context length, a model the provider rejects),
  ``unreachable`` (refused, DNS, breaker), ``timeout`` (no answer within the deadline),
  ``server_error`` (429/5xx after retries), ``bad_response`` (2xx but not a completion).

The verdicts other than ``ok`` mean the selector picks by the generated text label with
the correction off. Without a verdict the selector decides from its first real answer (an
endpoint that is down at start-up should not lose the correction forever); until then
its rounds hold. ``aeroweaver probe`` exits with ``EXIT_STATUS[kind]``.
"""

from __future__ import annotations

import string
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

from aeroweaver_edge.llm.client import (
    CallTag,
    ChatClient,
    LLMBadResponse,
    LLMError,
    LLMHTTPError,
    LLMTimeout,
)
from aeroweaver_edge.llm.logprobs import (
    first_row,
    fold_labels,
    is_degenerate,
    label_mass,
    text_of,
)

ProbeKind = Literal[
    "ok",
    "rejected",
    "degenerate",
    "low_label_mass",
    "auth",
    "not_found",
    "bad_request",
    "unreachable",
    "timeout",
    "server_error",
    "bad_response",
]
VERDICTS: frozenset[str] = frozenset({"ok", "rejected", "degenerate", "low_label_mass"})
"""Kinds that say what the endpoint's logprobs are; the rest say it did not answer."""

EXIT_STATUS: dict[str, int] = {
    "ok": 0,
    "rejected": 3,  # usable, correction off (text label)
    "degenerate": 3,
    "low_label_mass": 3,
    "auth": 4,
    "not_found": 5,
    "unreachable": 6,
    "timeout": 7,
    "bad_request": 8,
    "server_error": 8,
    "bad_response": 8,
}
"""``aeroweaver probe`` exit status per kind (1 and 2 stay internal and usage errors)."""

_FIX: dict[str, str] = {
    "auth": "check the key in the variable named by --api-key-env / llm.api_key_env",
    "not_found": "check the base URL (usually ends in /v1) and the model name",
    "bad_request": "the endpoint refuses the request itself (see its message)",
    "unreachable": "check the host, port and that the server runs",
    "timeout": "the endpoint is too slow or stuck; raise --llm-deadline or check the server",
    "server_error": "the endpoint is failing or rate-limiting; try again later",
    "bad_response": "the URL does not serve OpenAI chat completions",
}

PROBE_LABELS = tuple("ABCDEFGH")
MIN_LABEL_MASS = 0.3
_ACTIONS = (
    "hold position", "take off", "land", "return home", "climb 5 m", "orbit the landmark",
    "fly north 10 m", "fly east 10 m",
)  # fmt: skip


def probe_messages() -> list[dict[str, str]]:
    """A small multiple-choice question shaped like a real decision prompt."""
    options = "\n".join(f"{lb}. {act}" for lb, act in zip(PROBE_LABELS, _ACTIONS, strict=True))
    return [
        {
            "role": "system",
            "content": "You are the onboard decision agent of one UAV. Choose one action.",
        },
        {
            "role": "user",
            "content": "Battery 12 %, home is 40 m south.\n\n## Candidate actions\n"
            f"{options}\n\nAnswer with exactly one letter (A-H). Do not write anything else.",
        },
    ]


@dataclass(frozen=True)
class ProbeResult:
    kind: ProbeKind
    label_mass: float = 0.0
    detail: str = ""
    endpoint: str = ""
    model: str = ""
    single_token_labels: tuple[str, ...] | None = None
    """Letters A–Z that ``/tokenize`` reports as single tokens; ``None`` if not checkable."""

    @property
    def ok(self) -> bool:
        return self.kind == "ok"

    @property
    def correction_on(self) -> bool:
        return self.kind == "ok"

    @property
    def verdict(self) -> bool:
        """Whether this says what the logprobs are (else: the endpoint did not answer)."""
        return self.kind in VERDICTS

    @property
    def exit_status(self) -> int:
        return EXIT_STATUS[self.kind]

    @property
    def where(self) -> str:
        """``model @ endpoint`` as the one-liners name it."""
        return f"{self.model} @ {self.endpoint}" if self.endpoint else self.model or "endpoint"

    def line(self) -> str:
        """A printable one-liner for start-up logs and the run banner."""
        where = self.where
        if self.verdict:
            head = f"LLM probe [{self.kind}] {where}: label mass {self.label_mass:.2f}"
            tail = (
                "logprob selection with experience correction ON"
                if self.ok
                else "correction OFF, selecting by the generated text label"
            )
        else:
            head = f"LLM probe [{self.kind}] {where}"
            tail = (
                f"{_FIX[self.kind]}; no verdict on logprobs yet: the first answer decides "
                "the correction, rounds hold until the endpoint answers"
            )
        detail = f"; {self.detail}" if self.detail else ""
        return f"{head}{detail}; {tail}"

    def summary(self) -> str:
        """Alias of ``line()`` (the name ``app.py`` uses)."""
        return self.line()

    def unanswered_line(self) -> str:
        """One line for a command that refuses to start without an answering endpoint (a
        simulation or benchmark whose every decision would be a hold)."""
        detail = f": {self.detail}" if self.detail else ""
        fix = _FIX.get(self.kind, "check the endpoint")
        return (
            f"the LLM endpoint ({self.where}) did not answer the start-up probe "
            f"[{self.kind}]{detail}; {fix}"
        )


def classify_response(
    raw: dict[str, Any],
    labels: Sequence[str],
    min_label_mass: float = MIN_LABEL_MASS,
    *,
    endpoint: str = "",
    model: str = "",
) -> ProbeResult:
    """Classify any chat completion that was requested with logprobs."""
    text, finish = text_of(raw)
    row = first_row(raw)
    if row is None:
        return ProbeResult(
            "rejected", 0.0, f"response carries no logprobs (generated {text!r})", endpoint, model
        )
    if row.invalid is not None:
        return ProbeResult("degenerate", 0.0, row.invalid, endpoint, model)
    if is_degenerate(row):
        return ProbeResult(
            "degenerate", 0.0, "only 0 / -9999 values or an empty top list", endpoint, model
        )
    mass = label_mass(fold_labels(row.entries, set(labels)))
    if mass < min_label_mass:
        return ProbeResult(
            "low_label_mass",
            mass,
            f"under {min_label_mass:.2f} of the top-{len(row.tops)} mass on labels "
            f"(generated {text!r})",
            endpoint,
            model,
        )
    return ProbeResult("ok", mass, f"{len(row.tops)} top entries, finish {finish}", endpoint, model)


def error_kind(exc: LLMError) -> ProbeKind:
    """What a failed request says about the endpoint (never "rejected": only a retry
    without logprob parameters can tell that a 400/422 was about them)."""
    if isinstance(exc, LLMHTTPError):
        if exc.status in (401, 403):
            return "auth"
        if exc.status == 404:
            return "not_found"
        if exc.status in (408, 429) or exc.status >= 500:
            return "server_error"
        return "bad_request"
    if isinstance(exc, LLMTimeout):
        return "timeout"
    if isinstance(exc, LLMBadResponse):
        return "bad_response"
    return "unreachable"  # LLMUnreachable, LLMBreakerOpen, LLMConfigError


def classify_error(exc: LLMError, *, model: str = "") -> ProbeResult:
    """A failed request, classified by what the endpoint said."""
    kind = error_kind(exc)
    detail = f"HTTP {exc.status}: {exc.body}" if isinstance(exc, LLMHTTPError) else str(exc)
    if not isinstance(exc, LLMHTTPError):
        detail = f"{type(exc).__name__}: {detail}"
    return ProbeResult(kind, 0.0, detail, exc.endpoint, model)


def refused_logprobs(exc: LLMError, *, repeated: int = 0) -> ProbeResult:
    """A 400/422 with logprob parameters that a retry without them answered."""
    assert isinstance(exc, LLMHTTPError)
    times = f" ({repeated + 1} times)" if repeated else ""
    return ProbeResult(
        "rejected",
        0.0,
        f"HTTP {exc.status} with logprob parameters{times}, answered without them: {exc.body}",
        exc.endpoint,
    )


REFUSALS_TO_DECIDE = 2
"""Unexplained refusals (400/422 with logprobs, answered without them, not naming logprobs)
it takes to decide ``rejected``: one may be a transient proxy or server hiccup."""


def names_logprobs(exc: LLMError) -> bool:
    """The refusal says it is about the logprob parameters."""
    body = exc.body if isinstance(exc, LLMHTTPError) else ""
    return "logprob" in f"{exc} {body}".lower()


def refusal_verdict(exc: LLMError, earlier: int) -> ProbeResult | None:
    """After a refusal with logprob parameters that the same request without them answered:
    ``rejected`` when the refusal names logprobs or repeats (``earlier`` unexplained ones
    came before), else ``None``: this one decides nothing (that answer has no logprobs)."""
    if names_logprobs(exc) or earlier + 1 >= REFUSALS_TO_DECIDE:
        return refused_logprobs(exc, repeated=0 if names_logprobs(exc) else earlier)
    return None


def may_be_logprobs(exc: LLMError) -> bool:
    """A refusal that could be about the logprob parameters (to be told by a retry)."""
    return isinstance(exc, LLMHTTPError) and exc.status in (400, 422)


async def single_token_letters(client: ChatClient) -> tuple[str, ...] | None:
    """Letters that tokenise to exactly one token, via ``/tokenize`` (``None``: no route)."""
    out: list[str] = []
    for letter in string.ascii_uppercase:
        tokens = await client.tokenize(letter)
        if tokens is None:
            return None
        if len(tokens) == 1:
            out.append(letter)
    return tuple(out)


async def probe_endpoint(
    client: ChatClient,
    *,
    top_logprobs: int = 20,
    min_label_mass: float = MIN_LABEL_MASS,
    check_tokens: bool = True,
) -> ProbeResult:
    """One 1-token request with logprobs, classified. Never raises ``LLMError``."""
    tag = CallTag(purpose="probe")
    refusals = 0
    while True:
        try:
            result = await client.chat(
                probe_messages(), tag=tag, max_tokens=1, temperature=0, logprobs=True,
                top_logprobs=top_logprobs,
            )  # fmt: skip
            break
        except LLMError as exc:
            if not may_be_logprobs(exc):
                return classify_error(exc, model=client.model)
            try:  # the same request without logprob parameters tells what was refused
                await client.chat(probe_messages(), tag=tag, max_tokens=1, temperature=0)
            except LLMError as again:
                # Refused without logprobs too: the request itself is the problem (context
                # length, a model the provider does not serve), not logprob support.
                why = again if not may_be_logprobs(again) else exc
                return classify_error(why, model=client.model)
            verdict = refusal_verdict(exc, refusals)
            if verdict is not None:
                return replace(verdict, model=client.model)
            refusals += 1  # unexplained and the first: ask with logprobs once more
    probe = classify_response(
        result.raw, PROBE_LABELS, min_label_mass, endpoint=client.endpoint, model=client.model
    )
    if check_tokens:
        try:
            letters = await single_token_letters(client)
        except LLMError:
            letters = None
        if letters is not None:
            missing = [lb for lb in PROBE_LABELS if lb not in letters]
            note = f"labels not single tokens: {''.join(missing)}" if missing else ""
            detail = "; ".join(x for x in (probe.detail, note) if x)
            probe = replace(probe, detail=detail, single_token_labels=letters)
    return probe
