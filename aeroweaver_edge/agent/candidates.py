"""Enumerate every callable (skill, parameters) pair and give each a single-token label."""

from __future__ import annotations

import logging
import string
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from aeroweaver_edge.contracts.observation import Observation
from aeroweaver_edge.contracts.ports import Candidate
from aeroweaver_edge.contracts.skill_api import SkillContext, SkillParams

if TYPE_CHECKING:
    from aeroweaver_edge.skills import SkillRegistry

log = logging.getLogger(__name__)
LABELS = tuple(string.ascii_uppercase)


@dataclass(frozen=True)
class CandidateSet:
    candidates: tuple[Candidate, ...]
    params: dict[str, SkillParams]  # label -> validated parameter object
    overflow: int = 0  # options beyond the label budget; any overflow means hold

    @property
    def labels(self) -> list[str]:
        return [c.label for c in self.candidates]


def build_candidates(
    registry: SkillRegistry,
    active: Sequence[str],
    obs: Observation,
    ctx: SkillContext,
    max_labels: int = len(LABELS),
    allow: Callable[[str], bool] | None = None,
) -> CandidateSet:
    """One candidate per option of each active skill, in the order the skills were
    activated, deduplicated by invocation text and lettered A, B, C, ... ``allow(skill)``
    is asked for each skill that has options (the operator approval gate withholds a
    vehicle action it has no approval for)."""
    seen: set[str] = set()
    found: list[tuple[str, SkillParams, str]] = []
    for name in active:
        if name not in registry:
            continue
        skill = registry.get(name)
        try:
            options = skill.options(obs, ctx)
        except Exception:  # a broken skill loses its options, not the round
            log.exception("%s: options() of %s failed; skipping it this round", ctx.uav, name)
            continue
        if options and allow is not None and not allow(name):
            continue
        for params in options:
            text = params.invocation(name)
            if text not in seen:
                seen.add(text)
                found.append((name, params, text))
    budget = min(max_labels, len(LABELS))
    if len(found) > budget:
        return CandidateSet((), {}, overflow=len(found) - budget)
    cands = []
    params_by_label: dict[str, SkillParams] = {}
    for label, (name, params, text) in zip(LABELS, found, strict=False):
        cands.append(Candidate(label=label, skill=name, params=params.model_dump(), text=text))
        params_by_label[label] = params
    return CandidateSet(tuple(cands), params_by_label)


def seeded_order(items: Sequence[str], key: str) -> list[str]:
    """``items`` sorted by a hash of (``key``, item): one seeded permutation of every item
    that could appear under ``key``, restricted to ``items``. Two lists drawn under the same
    key list the items they share in the same relative order, whatever else each holds, so a
    condition that offers fewer skills does not reorder the ones it has in common (the
    benchmark's option-order control, docs/benchmark.md). Stable across Python versions and
    processes (sha256, not ``hash``)."""
    import hashlib

    def rank(item: str) -> bytes:
        return hashlib.sha256(f"{key}\x00{item}".encode()).digest()

    return sorted(dict.fromkeys(items), key=rank)
