"""One (task, condition) of a benchmark run: its episodes pooled over seeds, as the report
and the plots read them."""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from aeroweaver_edge.contracts.hold_reasons import HOLD_CAUSES
from aeroweaver_lab.bench.stats import bootstrap_ci


def add_known(a: int | None, b: int | None) -> int | None:
    """A sum that stays unknown once one part is (cells recorded before a count existed)."""
    return None if a is None or b is None else a + b


@dataclass
class CellStats:
    """One (task, condition): its episodes pooled over seeds."""

    task: str
    condition: str
    title: str
    seeds: list[int] = field(default_factory=list)
    returns: list[float] = field(default_factory=list)
    tokens: list[int] = field(default_factory=list)  # per episode, UAVs + central
    central_tokens: list[int] = field(default_factory=list)
    calls: list[int] = field(default_factory=list)
    latencies: list[float] = field(default_factory=list)
    decisions: int = 0
    invalid: int = 0
    holds: dict[str, int] = field(default_factory=lambda: dict.fromkeys(HOLD_CAUSES, 0))
    prompt: int = 0
    cached: int = 0
    model: str | None = None
    mismatches: list[str] = field(default_factory=list)
    central_rounds: int = 0
    reviews_asked: int = 0
    reviews_agreed: int = 0
    reviews_disagreed: int = 0
    revised_rounds: int = 0
    revision_calls: int | None = 0  # None: some cell predates the count (result version 2)
    paired: dict[tuple[int, int], float] = field(default_factory=dict)  # (seed, ep) -> return
    per_round: list[float] = field(default_factory=list)  # tokens / rounds, per episode
    setup: list[int] = field(default_factory=list)  # setup tokens spent in each episode
    setup_missing: int = 0  # runs whose Commander setup could not be measured
    picks: int = 0
    first_picks: int = 0
    finished: list[str] = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.returns)

    def paired_diffs(self, base: CellStats) -> list[float]:
        """This condition's return minus ``base``'s on every (seed, episode) both ran: the same
        world on both sides, so the difference is the conditions' and not the seeds'."""
        return [
            self.paired[k] - base.paired[k] for k in sorted(set(self.paired) & set(base.paired))
        ]

    def mean(self, xs: Sequence[float]) -> float | None:
        return statistics.fmean(xs) if xs else None

    @property
    def sd(self) -> float | None:
        return statistics.stdev(self.returns) if len(self.returns) > 1 else None

    def percentile(self, q: float) -> float | None:
        ys = sorted(self.latencies)
        if not ys:
            return None
        return ys[min(len(ys) - 1, round(q * (len(ys) - 1)))]

    @property
    def uncached_per_call(self) -> float | None:
        calls = sum(self.calls)
        return (self.prompt - self.cached) / calls if calls else None

    @property
    def uncached_per_decision(self) -> float | None:
        return (self.prompt - self.cached) / self.decisions if self.decisions else None

    @property
    def invalid_rate(self) -> float | None:
        return self.invalid / self.decisions if self.decisions else None

    @property
    def position_bias(self) -> float | None:
        """Share of picks (among >= 2 options) that took the first label listed."""
        return self.first_picks / self.picks if self.picks else None

    @property
    def ci(self) -> tuple[float, float] | None:
        return bootstrap_ci(self.returns)

    def absorb(self, other: CellStats) -> None:
        """Pool another cell's episodes into this one (a condition over all tasks)."""
        self.seeds += other.seeds
        self.returns += other.returns
        self.tokens += other.tokens
        self.central_tokens += other.central_tokens
        self.calls += other.calls
        self.latencies += other.latencies
        self.decisions += other.decisions
        self.invalid += other.invalid
        for k, v in other.holds.items():
            self.holds[k] = self.holds.get(k, 0) + v
        self.prompt += other.prompt
        self.cached += other.cached
        self.model = self.model or other.model
        self.central_rounds += other.central_rounds
        self.reviews_asked += other.reviews_asked
        self.reviews_agreed += other.reviews_agreed
        self.reviews_disagreed += other.reviews_disagreed
        self.revised_rounds += other.revised_rounds
        self.revision_calls = add_known(self.revision_calls, other.revision_calls)
        self.per_round += other.per_round
        self.setup += other.setup
        self.setup_missing += other.setup_missing
        self.picks += other.picks
        self.first_picks += other.first_picks
        self.finished += other.finished

    def figures(self) -> dict[str, Any]:
        """The table's figures as numbers (summary.json)."""

        def r(x: float | None, digits: int = 3) -> float | None:
            return None if x is None else round(x, digits)

        episodes = len(self.calls)
        ci = self.ci
        return {
            "cells": len(self.seeds),
            "episodes": episodes,
            "return_mean": r(self.mean(self.returns)),
            "return_sd": r(self.sd),
            "return_ci95": None if ci is None else [r(ci[0]), r(ci[1])],
            "tokens_per_episode": r(self.mean(self.tokens), 1),
            "tokens_per_round": r(self.mean(self.per_round), 1),
            "setup_tokens_per_episode": r(self.mean(self.setup), 1),
            "setup_missing_runs": self.setup_missing,
            "position_bias": r(self.position_bias, 4),
            "picks": self.picks,
            "central_tokens_per_episode": r(self.mean(self.central_tokens), 1),
            "llm_calls_per_episode": r(self.mean(self.calls), 2),
            "decisions": self.decisions,
            "latency_p50_s": r(self.percentile(0.5)),
            "latency_p95_s": r(self.percentile(0.95)),
            "uncached_prompt_per_call": r(self.uncached_per_call, 1),
            "uncached_prompt_per_decision": r(self.uncached_per_decision, 1),
            "invalid_rate": r(self.invalid_rate, 4),
            "holds_per_episode": {
                k: r(v / episodes, 2) for k, v in self.holds.items() if v and episodes
            },
            "model": self.model,
            "central_rounds": self.central_rounds,
            "reviews_agreed": self.reviews_agreed,
            "reviews_asked": self.reviews_asked,
            "reviews_disagreed": self.reviews_disagreed,
            "revised_rounds": self.revised_rounds,
            "revision_calls": self.revision_calls,
        }


__all__ = ["CellStats", "add_known"]
