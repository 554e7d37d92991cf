"""Start-up endpoint probe: can this endpoint's first-token logprobs drive the selector?

One 1-token request with logprobs, classified as

* ``ok`` — a real distribution with enough mass on the labels: experience correction on;
* ``rejected`` — the endpoint refuses logprobs (HTTP 400/422) or silently drops them;
* ``degenerate`` — only 0 / -9999 values or an empty top list (an argmax, not a distribution);
* ``low_label_mass`` — labels get too little of the mass (e.g. a base model);
* ``unreachable`` — no answer at all (connection, deadline, 5xx, auth, breaker).

Anything but ``ok`` means the selector falls back to the generated text label with the
correction off; ``unreachable`` is "unknown", which the selector re-decides from its first
real answer (an endpoint that is down at start-up should not lose the correction forever).
"""

from __future__ import annotations

import string
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

from aeroweaver_edge.llm.client import CallTag, ChatClient, LLMError, LLMHTTPError
from aeroweaver_edge.llm.logprobs import (
    first_row,
    fold_labels,
    is_degenerate,
    label_mass,
    text_of,
)

ProbeKind = Literal["ok", "rejected", "degenerate", "low_label_mass", "unreachable"]

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

    def line(self) -> str:
        """A printable one-liner for start-up logs and the run banner."""
        where = f"{self.model} @ {self.endpoint}" if self.endpoint else self.model or "endpoint"
        head = f"LLM probe [{self.kind}] {where}: label mass {self.label_mass:.2f}"
        tail = (
            "logprob selection with experience correction ON"
            if self.ok
            else "correction OFF, selecting by the generated text label"
        )
        detail = f"; {self.detail}" if self.detail else ""
        return f"{head}{detail}; {tail}"

    def summary(self) -> str:
        """Alias of ``line()`` (the name ``app.py`` uses)."""
        return self.line()


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


def classify_error(exc: LLMError, *, model: str = "") -> ProbeResult:
    """A failed request: 400/422 means logprobs were refused; anything else is unreachable."""
    if isinstance(exc, LLMHTTPError) and exc.status in (400, 422):
        return ProbeResult("rejected", 0.0, f"HTTP {exc.status}: {exc.body}", exc.endpoint, model)
    return ProbeResult("unreachable", 0.0, f"{type(exc).__name__}: {exc}", exc.endpoint, model)


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
    try:
        result = await client.chat(
            probe_messages(),
            tag=CallTag(purpose="probe"),
            max_tokens=1,
            temperature=0,
            logprobs=True,
            top_logprobs=top_logprobs,
        )
    except LLMError as exc:
        return classify_error(exc, model=client.model)
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
