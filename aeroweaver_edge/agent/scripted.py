"""A deterministic scorer with the LLM selector's interface: the task's reference policy.

It is a heuristic, not a model: results from it say nothing about LLM quality. Each task
definition carries a scripted reference policy (``TaskDefinition.reference``, see
``aeroweaver_edge.tasks``) that gives every labelled candidate a utility from the UAV's own
observation; this scorer turns the utilities into log-softmax scores, so the same ``choose``
arithmetic (and the experience correction) applies as for an LLM. The policy is looked up by
the request's task; a task the registry does not know gets only the rules every policy
shares (hold, return in bounds, explore).

Degraded bases (issue 24: the correction exists to fix a weak base, so it must be shown on
one): ``hold-biased`` adds ``HOLD_BIAS`` to ``hold_position``; ``position-biased`` shuffles
the options with a seeded permutation per decision and adds ``POSITION_BIAS`` to the one
shown first (what a small LLM answering ``A`` does when the order changes every round);
``noisy[:SD]`` adds seeded Gaussian noise (default SD ``NOISE_SD``) to every utility; any
base with ``@T`` divides the utilities by T before the log-softmax (same argmax, gaps T
times smaller: room for the correction to act). The
randomness is a function of (task, UAV, episode, round, own position) only, so in-process and
``--processes`` runs agree and paired runs (beta = 0 against beta > 0) see the same noise
in the same state.
A daemon runs the base its config names (``[agent] scripted_base``);
``AEROWEAVER_SCRIPTED_BASE`` overrides the file and ``--base`` both (``agent.choices``).
"""

from __future__ import annotations

import math
import os
import random
from dataclasses import dataclass
from functools import cache
from typing import Final

from aeroweaver_edge.contracts.defaults import HOLD_SKILL
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.contracts.ports import DecisionRequest
from aeroweaver_edge.contracts.scores import LabelScores
from aeroweaver_edge.contracts.selector_specs import ScriptedBaseSpec
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


HOLD_BIAS: Final = 3.0
POSITION_BIAS: Final = 3.0
ENV_BASE: Final = "AEROWEAVER_SCRIPTED_BASE"


@dataclass(frozen=True)
class Base(ScriptedBaseSpec):
    """A scripted base: the reference policy, optionally degraded (module docstring)."""

    def _rng(self, request: DecisionRequest) -> random.Random:
        o = request.observation
        # a str seed is hashed with SHA-512: the same in every process (no PYTHONHASHSEED)
        # the position tells layouts (seed sequences) apart: episode e of every sequence
        # would otherwise draw the same noise
        key = f"{self.kind}|{self.seed}|{request.task}|{o.uav}|{o.episode}|{o.round}|{o.own.pos}"
        return random.Random(key)

    def degrade(self, request: DecisionRequest, utils: dict[str, float]) -> dict[str, float]:
        """The base's utilities from the reference ones (a new dict)."""
        out = dict(utils)
        if self.kind == "hold-biased":
            for c in request.candidates:
                if c.skill == HOLD_SKILL and c.label in out:
                    out[c.label] += HOLD_BIAS
        elif self.kind == "position-biased":
            order = [c.label for c in request.candidates if c.label in out]
            if order:
                self._rng(request).shuffle(order)
                out[order[0]] += POSITION_BIAS
        elif self.kind == "noisy":
            rng = self._rng(request)
            for c in request.candidates:  # candidate order: one draw per option, stable
                if c.label in out:
                    out[c.label] += rng.gauss(0.0, self.sd)
        return out


class DegradedScorer(ReferenceScorer):
    """The reference scorer with a degraded ``Base`` (a testbed with headroom)."""

    def __init__(self, base: Base) -> None:
        super().__init__(base.temperature)
        self.base = base
        self.name = f"scripted:{base.name}"

    async def score(self, request: DecisionRequest) -> LabelScores:
        if not request.candidates:
            return LabelScores(logprobs={})
        utils = self.base.degrade(request, reference_policy(request.task).utilities(request))
        return LabelScores(logprobs=log_softmax(utils, self.temperature))


def scorer_for(base: str | Base) -> ReferenceScorer:
    """The scorer of a base name (``ValueError`` for an unknown one)."""
    b = Base.parse(base) if isinstance(base, str) else base
    return ReferenceScorer() if b == Base() else DegradedScorer(b)


def scorer_from_env() -> ReferenceScorer:
    """The scorer ``AEROWEAVER_SCRIPTED_BASE`` alone names (unset or empty: the reference;
    a daemon resolves it against its config with ``agent.choices``); a bad value is a
    ``UserError`` (one line, exit 2)."""
    try:
        return scorer_for(os.environ.get(ENV_BASE, "") or "reference")
    except ValueError as exc:
        raise UserError(
            f"{ENV_BASE}: {exc}", f"unset it or set e.g. {ENV_BASE}=reference"
        ) from None


__all__ = [
    "ENV_BASE",
    "Base",
    "DegradedScorer",
    "ReferenceScorer",
    "log_softmax",
    "reference_policy",
    "scorer_for",
    "scorer_from_env",
]
