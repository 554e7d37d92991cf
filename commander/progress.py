"""Aggregates progress reports: the Commander's (read-only) view of the mission."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from aeroweaver_edge.contracts.hold_reasons import count_causes
from aeroweaver_edge.contracts.wire import ProgressReport


@dataclass
class UavProgress:
    uav: str
    role: str = ""
    last: ProgressReport | None = None
    reports: int = 0
    holds: int = 0
    prompt_tokens: int = 0
    prompt_cached: int = 0  # of prompt_tokens, from the endpoint's prompt cache
    completion_tokens: int = 0
    messages_sent: int = 0
    messages_dropped: int = 0
    llm_calls: int = 0  # requests sent to the LLM endpoint (answered or not)
    llm_class: str = ""  # the selector's latest logprob class (probe kind)
    deadline_misses: int = 0  # rounds the daemon did not finish within its deadline
    holds_by_cause: dict[str, int] = field(default_factory=lambda: count_causes(()))
    # Per-round latency, bounded: a long field mission must not grow the Commander.
    latencies_s: deque[float] = field(default_factory=lambda: deque(maxlen=4096))
    cpu_s: deque[float] = field(default_factory=lambda: deque(maxlen=4096))
    rejected: dict[str, int] = field(default_factory=dict)  # the daemon's refusals (latest)
    missing_messages: int = 0  # expected messages that never reached it (latest)
    rewarded: int = 0  # round reports that carried a reward (the field usually has none)
    reward_sum: float = 0.0
    first_round: int | None = None  # the daemon's own round numbers this mission spans


@dataclass
class ProgressBoard:
    mission_id: str
    uavs: dict[str, UavProgress] = field(default_factory=dict)
    foreign: int = 0  # reports for another mission, or whose sender is not the reporting UAV
    ready: dict[str, str] = field(default_factory=dict)  # uav -> role it acknowledged
    episode_tokens: dict[int, int] = field(default_factory=dict)  # decision tokens per episode
    max_episodes: int = 4096  # bound: reports cannot grow the board without limit

    def add(self, rep: ProgressReport) -> bool:
        """Take a report; False (counted in ``foreign``) if it is not for this mission or
        its sender is not the reporting UAV."""
        if rep.mission_id != self.mission_id or rep.h.sender != rep.uav:
            self.foreign += 1
            return False
        if rep.phase == "ready":
            self.ready[rep.uav] = rep.role
            return True
        if rep.phase == "experience":
            return True  # a shared-experience tally: for the barrier between episodes
        fresh = rep.phase == "round" and rep.episode not in self.episode_tokens
        if fresh and len(self.episode_tokens) >= self.max_episodes:
            self.foreign += 1  # a flood of made-up episode numbers
            return False
        p = self.uavs.setdefault(rep.uav, UavProgress(rep.uav))
        # Counters are cumulative in the daemon: the latest report has them all.
        p.rejected = dict(rep.rejected)
        p.missing_messages = rep.missing_messages
        if rep.phase == "final":
            return True
        p.role = rep.role
        p.last = rep
        p.reports += 1
        p.holds += rep.held
        if rep.hold_cause is not None:
            p.holds_by_cause[rep.hold_cause] += 1
        p.deadline_misses += rep.hold_cause == "deadline"
        p.llm_class = rep.llm_class or p.llm_class
        p.prompt_tokens += rep.prompt_tokens
        p.prompt_cached += rep.prompt_cached
        p.completion_tokens += rep.completion_tokens
        p.messages_sent += rep.messages_sent
        p.messages_dropped += rep.messages_dropped
        p.llm_calls += rep.llm_calls
        p.latencies_s.append(rep.latency_s)
        p.cpu_s.append(rep.cpu_s)
        if rep.reward is not None and math.isfinite(rep.reward):
            p.rewarded += 1
            p.reward_sum += rep.reward
        if p.first_round is None:
            p.first_round = rep.round
        tokens = rep.prompt_tokens + rep.completion_tokens
        self.episode_tokens[rep.episode] = self.episode_tokens.get(rep.episode, 0) + tokens
        return True
