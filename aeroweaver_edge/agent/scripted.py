"""A deterministic scorer with the LLM selector's interface: the task's reference policy.

It is a heuristic, not a model: results from it say nothing about LLM quality. Each task
definition carries a scripted reference policy (``TaskDefinition.reference``, see
``aeroweaver_edge.tasks``) that gives every labelled candidate a utility from the UAV's own
observation; this scorer turns the utilities into log-softmax scores, so the same ``choose``
arithmetic (and the experience correction) applies as for an LLM. The policy is looked up by
the request's task; a task the registry does not know gets only the rules every policy
shares (hold, return in bounds, explore).
"""

from __future__ import annotations

import math
from functools import cache

from aeroweaver_edge.ports import DecisionRequest
from aeroweaver_edge.scores import LabelScores
from aeroweaver_edge.tasks.base import ReferencePolicy


class _SharedRulesOnly:
    def utilities(self, request: DecisionRequest) -> dict[str, float]:
        from aeroweaver_edge.tasks import policy

        return policy.score_all(request, lambda c: None, wants_something=False)


@cache
def reference_policy(task: str) -> ReferencePolicy:
    """The reference policy of ``task`` (imports only that task's module)."""
    from aeroweaver_edge.tasks import TASK_NAMES, definition

    if task not in TASK_NAMES:
        return _SharedRulesOnly()
    return definition(task).reference


def log_softmax(utilities: dict[str, float], temperature: float = 1.0) -> dict[str, float]:
    if not utilities:
        return {}
    scaled = {k: u / temperature for k, u in utilities.items()}
    top = max(scaled.values())
    log_z = top + math.log(sum(math.exp(u - top) for u in scaled.values()))
    return {k: u - log_z for k, u in scaled.items()}


class ReferenceScorer:
    """``Selector`` that scores candidates with the task's scripted reference policy."""

    name = "scripted:reference"

    def __init__(self, temperature: float = 1.0) -> None:
        if not (math.isfinite(temperature) and temperature > 0):
            raise ValueError(f"temperature must be positive and finite, got {temperature!r}")
        self.temperature = temperature

    @property
    def label_budget(self) -> int | None:
        return None

    async def score(self, request: DecisionRequest) -> LabelScores:
        if not request.candidates:
            return LabelScores(logprobs={})
        utils = reference_policy(request.task).utilities(request)
        return LabelScores(logprobs=log_softmax(utils, self.temperature))

    async def aclose(self) -> None:
        return None


__all__ = ["ReferenceScorer", "log_softmax", "reference_policy"]
