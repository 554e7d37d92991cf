"""What a selector returns and what the choice rule decides: plain types at the bottom of
the package, so the Selector port (``ports``), the LLM parser (``llm.logprobs``) and the
choice arithmetic (``agent.scoring``) all import them from here and never from each other.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

NOT_OBSERVED = -9999.0  # providers' floor for "outside the top list"


@dataclass(frozen=True)
class LabelScores:
    """What a selector backend returns for one decision."""

    logprobs: Mapping[str, float]
    """Base score per candidate label that came back, labels already normalised."""
    omitted_bound: float = -math.inf
    """Upper bound (log-prob) on any candidate label missing from ``logprobs``."""
    text_label: str | None = None
    """The label the model generated, used when its logprobs are unusable."""
    logprobs_usable: bool = True
    prompt_tokens: int = 0
    completion_tokens: int = 0
    cached_tokens: int = 0
    latency_s: float = 0.0
    error: str | None = None
    extra: Mapping[str, object] = field(default_factory=dict)


@dataclass(frozen=True)
class Choice:
    label: str | None  # None means hold
    reason: str
    corrected: bool = False  # the experience correction changed the pick
    base: Mapping[str, float] = field(default_factory=dict)
    corrected_scores: Mapping[str, float] = field(default_factory=dict)


def omitted_bound(top_logprobs: Sequence[float], requested: int) -> float:
    """Upper bound on the log-prob of any token missing from a returned top list.

    The leftover mass ``1 - sum(p)`` always bounds it; when the list came back full, its
    smallest entry does too. ``NOT_OBSERVED`` floors are not observations and are ignored.
    """
    seen = [lp for lp in top_logprobs if lp > NOT_OBSERVED and math.isfinite(lp)]
    leftover = 1.0 - sum(math.exp(lp) for lp in seen)
    bound = math.log(leftover) if leftover > 1e-12 else -math.inf
    if seen and len(seen) >= requested:
        bound = min(bound, min(seen))
    return bound
