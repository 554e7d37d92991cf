"""Turn one chat completion into ``LabelScores`` (DESIGN §4 step 4).

Rules, decided once here:

* **Which row**: the first entry of ``choices[0].logprobs.content`` (the first *answer*
  token). A ``reasoning_content`` array next to it is ignored: reasoning tokens are not the
  answer, and a model that reasons before answering yields no first-token distribution.
* **Normalisation**: a token is stripped of surrounding whitespace; a remaining single
  ASCII letter is upper-cased (``" a"`` → ``"A"``). Longer tokens keep their case and never
  match a label, so ``"An"`` or ``"Answer"`` cannot be mistaken for ``A``.
* **Variant folding**: all spellings of a label (``"A"``, ``" A"``, ``"a"``) are combined
  with log-sum-exp. The spellings are disjoint next tokens, so their summed probability *is*
  the probability that the model answers with that label; keeping only the max would
  under-count labels whose mass is split. Caveat for the bound rule: the full-list floor
  bounds each *missing token*; a label with several missing spellings is bounded by their
  sum, which only the leftover-mass part of the bound covers exactly. In practice a label
  that is absent has every spelling below the floor and the leftover mass is small.
* ``-9999`` (and anything at or below it, or non-finite) means "not observed": it is neither
  a score nor an observation for the omitted-label bound.
* **Omitted bound** uses every returned entry (labels and other tokens alike) via
  ``scoring.omitted_bound``: the leftover mass and, if the list came back full, its floor.
  The sampled token counts towards the leftover mass but never towards the floor (it may
  lie outside the list, e.g. when sampling at temperature > 0).
* **Degenerate**: an empty top list, or every value in {0, -9999}, carries no distribution
  (seen with DeepSeek). Then ``logprobs_usable=False`` and the generated text label is used.
* **Invalid**: a log-probability is at most 0. A positive value anywhere in the row (beyond
  float rounding, ``POSITIVE_TOLERANCE``) means the endpoint does not send log-probabilities
  (raw logits, or garbage), so none of the row is a score: it is treated as unusable, like a
  degenerate row, and the generated text label decides.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from aeroweaver_edge.contracts.scores import NOT_OBSERVED, LabelScores, omitted_bound
from aeroweaver_edge.llm.client import Usage

OK_FINISH = frozenset({"stop", "length"})
_MAX_TEXT = 40
POSITIVE_TOLERANCE = 1e-6
"""A log-probability above 0 by more than this is no log-probability (float rounding of a
certain token gives 1e-7 at most)."""


def normalise_token(token: str) -> str:
    """Strip whitespace; upper-case a lone ASCII letter. Everything else is left alone."""
    t = token.strip()
    if len(t) == 1 and t.isascii() and t.isalpha():
        return t.upper()
    return t


def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)


def observed(logprob: float) -> bool:
    return math.isfinite(logprob) and logprob > NOT_OBSERVED


def logsumexp(values: Sequence[float]) -> float:
    top = max(values)
    return top + math.log(sum(math.exp(v - top) for v in values))


@dataclass(frozen=True)
class Row:
    """The first answer token: its top list (``token -> logprob``, duplicates keep their
    best value) and the sampled token, which may lie outside the list."""

    tops: dict[str, float]
    sampled: tuple[str, float] | None
    invalid: str | None = None  # why the row holds no log-probabilities (a positive value)

    @property
    def entries(self) -> dict[str, float]:
        """Every observation: the top list plus the sampled token."""
        out = dict(self.tops)
        if self.sampled is not None:
            token, value = self.sampled
            out[token] = max(value, out.get(token, -math.inf))
        return out

    def bound(self, requested: int) -> float:
        """``scoring.omitted_bound`` made safe for a sampled token outside the list: the
        floor may only come from the top list, the leftover mass from every observation."""
        top_only = omitted_bound(list(self.tops.values()), requested)
        everything = list(self.entries.values())
        return min(top_only, omitted_bound(everything, len(everything) + 1))


def _entry(item: object) -> tuple[str, float] | None:
    if not isinstance(item, Mapping):
        return None
    token, value = item.get("token"), _number(item.get("logprob"))
    if isinstance(token, str) and value is not None:
        return token, value
    return None


def first_row(raw: Mapping[str, Any]) -> Row | None:
    """The first ``choices[0].logprobs.content`` entry, or ``None`` when the response
    carries no content logprobs at all (logprobs ignored, or only reasoning tokens)."""
    try:
        lp = raw["choices"][0].get("logprobs")
    except (KeyError, IndexError, TypeError, AttributeError):
        return None
    if not isinstance(lp, Mapping):
        return None
    rows = lp.get("content")
    if not isinstance(rows, list) or not rows or not isinstance(rows[0], Mapping):
        return None
    row = rows[0]
    tops: dict[str, float] = {}
    items = row.get("top_logprobs")
    positive: float | None = None
    for item in items if isinstance(items, list) else []:
        entry = _entry(item)
        if entry is not None:  # vLLM may append the sampled token again: keep the best
            tops[entry[0]] = max(entry[1], tops.get(entry[0], -math.inf))
            if entry[1] > POSITIVE_TOLERANCE:
                positive = max(entry[1], positive or entry[1])
    sampled = _entry(row)
    if sampled is not None and sampled[1] > POSITIVE_TOLERANCE:
        positive = max(sampled[1], positive or sampled[1])
    if positive is not None:
        why = f"positive logprob {positive:+.3g} (a log-probability is at most 0)"
        return Row({}, None, why)
    tops = {t: min(v, 0.0) for t, v in tops.items()}  # rounding noise above 0 is 0
    if sampled is not None:
        sampled = (sampled[0], min(sampled[1], 0.0))
    return Row(tops, sampled)


def is_degenerate(row: Row) -> bool:
    """No distribution: an empty top list, or only 0 / -9999 values."""
    if not row.tops:
        return True
    return all(v == 0.0 or v <= NOT_OBSERVED for v in row.entries.values())


def fold_labels(entries: Mapping[str, float], labels: Collection[str]) -> dict[str, float]:
    """Per candidate label, the log-sum-exp of all its observed spellings."""
    found: dict[str, list[float]] = {}
    for token, value in entries.items():
        if not observed(value):
            continue
        label = normalise_token(token)
        if label in labels:
            found.setdefault(label, []).append(value)
    return {label: logsumexp(values) for label, values in found.items()}


def label_mass(logprobs: Mapping[str, float]) -> float:
    return sum(math.exp(v) for v in logprobs.values() if observed(v))


def text_of(raw: Mapping[str, Any]) -> tuple[str | None, str | None]:
    """Normalised generated text (capped) and ``finish_reason``."""
    try:
        choice = raw["choices"][0]
    except (KeyError, IndexError, TypeError):
        return None, None
    if not isinstance(choice, Mapping):
        return None, None
    message = choice.get("message")
    content = message.get("content") if isinstance(message, Mapping) else None
    text = normalise_token(content)[:_MAX_TEXT] if isinstance(content, str) else None
    finish = choice.get("finish_reason")
    return (text or None), (finish if isinstance(finish, str) else None)


def parse_label_scores(
    raw: Mapping[str, Any],
    labels: Sequence[str],
    requested: int,
    *,
    usage: Usage | None = None,
    latency_s: float = 0.0,
    use_logprobs: bool = True,
) -> LabelScores:
    """Parse a chat completion into ``LabelScores`` for the candidate ``labels``.

    ``requested`` is the ``top_logprobs`` value sent (decides whether the list came back
    full). ``use_logprobs=False`` (the probe found logprobs unusable) keeps the parsed values
    for diagnostics but makes the selector use the generated text label.
    """
    usage = usage or Usage()
    text_label, finish = text_of(raw)
    common: dict[str, Any] = {
        "text_label": text_label,
        "prompt_tokens": usage.prompt_tokens,
        "completion_tokens": usage.completion_tokens,
        "cached_tokens": usage.cached_tokens,
        "latency_s": latency_s,
    }
    extra: dict[str, object] = {"finish_reason": finish}
    if finish is not None and finish not in OK_FINISH:
        return LabelScores(
            logprobs={},
            logprobs_usable=False,
            error=f"finish_reason {finish!r} (expected stop or length)",
            extra=extra,
            **common,
        )
    row = first_row(raw)
    if row is None:
        extra["unusable"] = "no content logprobs in response"
        return LabelScores(logprobs={}, logprobs_usable=False, extra=extra, **common)
    if row.invalid is not None:
        extra["unusable"] = row.invalid
        extra["invalid_logprobs"] = True
        return LabelScores(logprobs={}, logprobs_usable=False, extra=extra, **common)
    extra["returned"] = len(row.tops)
    if is_degenerate(row):
        extra["unusable"] = "degenerate logprobs (empty, or only 0 / -9999)"
        extra["degenerate"] = True
        return LabelScores(logprobs={}, logprobs_usable=False, extra=extra, **common)
    folded = fold_labels(row.entries, set(labels))
    extra["label_mass"] = label_mass(folded)
    if not use_logprobs:
        extra["unusable"] = "correction off (endpoint probe)"
    return LabelScores(
        logprobs=folded,
        omitted_bound=row.bound(requested),
        logprobs_usable=use_logprobs,
        extra=extra,
        **common,
    )
