"""The selector's arithmetic (DESIGN §4 step 4), pure and separately testable.

Base score ``z_i`` is the first-token log-probability of label i. The experience correction
adds ``beta * A(s, skill_i)``. A label the provider did not return may still be large enough
to win after its own correction; the *bound rule* keeps the corrected winner only when no
omitted label could beat it, otherwise it falls back to the highest base score.
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


def _argmax(scores: Mapping[str, float], order: Sequence[str]) -> str:
    best = None
    for label in order:  # ties go to the earlier label: deterministic
        if label in scores and (best is None or scores[label] > scores[best]):
            best = label
    assert best is not None
    return best


def choose(
    scores: LabelScores,
    labels: Sequence[str],
    advantages: Mapping[str, float],
    beta: float,
) -> Choice:
    """Pick one label, or ``None`` (hold) when nothing usable came back."""
    if scores.error is not None:
        return Choice(None, f"selector error: {scores.error}")
    if not scores.logprobs_usable:
        if scores.text_label in labels:
            return Choice(scores.text_label, "text label (logprobs unusable, correction off)")
        return Choice(None, f"no usable label (generated {scores.text_label!r})")
    base = {
        lb: lp
        for lb, lp in scores.logprobs.items()
        if lb in labels and lp > NOT_OBSERVED and math.isfinite(lp)
    }
    if not base:
        return Choice(None, "no candidate label among returned tokens")
    base_winner = _argmax(base, labels)
    if beta == 0:
        return Choice(base_winner, "base score", base=base, corrected_scores=base)
    corrected = {lb: z + beta * advantages.get(lb, 0.0) for lb, z in base.items()}
    winner = _argmax(corrected, labels)
    if winner != base_winner:
        for lb in labels:
            if (
                lb not in base
                and scores.omitted_bound + beta * advantages.get(lb, 0.0) > corrected[winner]
            ):
                return Choice(
                    base_winner,
                    f"bound rule: omitted {lb} could beat corrected {winner}",
                    base=base,
                    corrected_scores=corrected,
                )
    return Choice(
        winner,
        "corrected score" if winner != base_winner else "base score (correction agrees)",
        corrected=winner != base_winner,
        base=base,
        corrected_scores=corrected,
    )
