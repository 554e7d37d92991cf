"""Why a UAV held in a round: a closed set of causes, carried in ``RoundOutcome`` and on
the wire (``ProgressReport.hold_cause``) and counted as ``holds_by_cause`` in run
summaries, so a chosen ``hold_position()`` never looks like a failure and vice versa.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Final, Literal, get_args

HoldCause = Literal[
    "chosen",  # the agent's chosen skill holds (hold_position(), or a skill that stays put)
    "llm_failure",  # no answer: HTTP error, timeout, unreachable, breaker open
    "invalid_answer",  # an answer, but no usable label in it
    "deadline",  # the daemon missed its own round deadline
    "safety_gate",  # the gate turned the command into a hold (separation, non-finite, ...)
    "no_candidates",  # nothing callable, or more options than labels
    "no_assignment",  # no mission assignment yet (or it ended)
    "skill_error",  # the chosen skill's executor raised
]

HOLD_CAUSES: Final[tuple[HoldCause, ...]] = get_args(HoldCause)

DESCRIPTIONS: Final[dict[HoldCause, str]] = {
    "chosen": "chosen by the agent",
    "llm_failure": "LLM call failed",
    "invalid_answer": "no usable label in the answer",
    "deadline": "round deadline missed in the daemon",
    "safety_gate": "held by the safety gate",
    "no_candidates": "no callable candidates / label overflow",
    "no_assignment": "no mission assignment",
    "skill_error": "skill executor failed",
}


def after_gate(held: bool, executor_failed: bool, violations: Iterable[str]) -> HoldCause | None:
    """The cause of a hold once the agent chose a skill: its executor raised, the gate
    refused the command, or the skill itself holds (a chosen hold)."""
    if not held:
        return None
    if executor_failed:
        return "skill_error"
    return "safety_gate" if any(True for _ in violations) else "chosen"


def count_causes(causes: Iterable[str | None]) -> dict[str, int]:
    """Holds per cause, every cause present (0 when none), in the canonical order."""
    counts: dict[str, int] = dict.fromkeys(HOLD_CAUSES, 0)
    for cause in causes:
        if cause is not None and cause in counts:
            counts[cause] += 1
    return counts


def format_counts(counts: dict[str, int]) -> str:
    """``llm_failure 3, chosen 1`` (non-zero causes only), or ``none``."""
    parts = [f"{cause} {n}" for cause, n in counts.items() if n]
    return ", ".join(parts) if parts else "none"
