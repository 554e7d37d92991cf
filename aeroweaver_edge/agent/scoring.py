"""The selector's arithmetic (DESIGN §4 step 4), pure and separately testable.

Base score ``z_i`` is the first-token log-probability of label i. The experience correction
adds ``beta * A(s, skill_i)``. A label the provider did not return may still be large enough
to win after its own correction; the *bound rule* keeps the corrected winner only when no
omitted label could beat it, otherwise it falls back to the highest base score.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from aeroweaver_edge.contracts.scores import NOT_OBSERVED, Choice, LabelScores, omitted_bound

__all__ = ["NOT_OBSERVED", "Choice", "LabelScores", "choose", "omitted_bound"]


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
