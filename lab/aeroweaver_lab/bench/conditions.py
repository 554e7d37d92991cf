"""The benchmark's conditions (DESIGN §10; paper §4): what each one changes in a run.

| name | who decides | skills per UAV | coordination reports | beta | memory |
|---|---|---|---|---|---|
| aeroweaver | each UAV's own LLM (first-token logprobs) | top-K for its role | yes | 0.8 | shared |
| centralized | central node, one call per round | full catalogue | yes | 0 | none used |
| hmas2 | central plan, local reviews, revision on dissent | full catalogue | yes | 0 | none used |
| no_activation | as aeroweaver | full catalogue (no role filter, no top-K) | yes | 0.8 | shared |
| no_coordination | as aeroweaver | top-K | task messages only | 0.8 | shared |
| beta0 | as aeroweaver | top-K | yes | 0 | (not used) |
| scripted | the task's reference policy (a heuristic, no LLM) | top-K | yes | 0 | - |

Every condition lists options in one seeded order per (task, seed, UAV)
(``SwarmOptions.option_order = "seeded"``, set by the runner): skills two conditions share
keep their relative order, so a position-biased model is handed the same skill for ``A``
whenever the same skills are on offer.

The baselines get no interaction history either (their prompts have none), as in the paper
("all 22 skills without reward memory"); they share the UAVs' executors, safety gate and
invalid -> hold rule.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Final, Literal

from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.contracts import defaults as d
from aeroweaver_edge.orchestration.swarm import SwarmOptions
from aeroweaver_lab.baselines.wiring import CentralBaseline


@dataclass(frozen=True)
class Condition:
    name: str
    title: str  # column header in tables and plots
    selector: Literal["llm", "scripted"] = "llm"
    baseline: Literal["none", "centralized", "hmas2"] = "none"
    activation: Literal["topk", "full"] = "topk"
    coordination: bool = True
    beta: float = d.BETA
    history: bool = True
    stages: int = 1  # LLM calls one after another inside a round (sets the round deadline)


CONDITIONS: Final[dict[str, Condition]] = {
    c.name: c
    for c in (
        Condition("aeroweaver", "AeroWeaver"),
        Condition(
            "centralized", "Centralized", baseline="centralized", activation="full", beta=0.0,
            history=False,
        ),
        Condition(
            "hmas2", "HMAS-2", baseline="hmas2", activation="full", beta=0.0, history=False,
            stages=3,
        ),
        Condition("no_activation", "w/o activation", activation="full"),
        Condition("no_coordination", "w/o coordination", coordination=False),
        Condition("beta0", "beta = 0", beta=0.0),
        Condition("scripted", "Scripted reference", selector="scripted", beta=0.0),
    )
}  # fmt: skip
LLM_CONDITIONS: Final = tuple(n for n, c in CONDITIONS.items() if c.selector == "llm")


def round_deadline_s(cond: Condition, llm_deadline_s: float) -> float:
    """A round may take every sequential LLM call's deadline plus room for the inbox wait,
    the central node's gathering and a review wait: load makes a run slower, not wrong."""
    if cond.selector == "scripted":
        return 10.0
    return cond.stages * llm_deadline_s + 15.0 * cond.stages


def swarm_options(
    cond: Condition,
    *,
    task: str,
    seed: int,
    episodes: int,
    rounds: int,
    llm: LLMConfig,
    deadline_s: float | None,
    trace_path: Path,
    memory_dir: Path,
) -> SwarmOptions:
    return SwarmOptions(
        task=task,
        seed=seed,
        episodes=episodes,
        max_rounds=rounds,
        selector=cond.selector,
        llm=llm,
        beta=cond.beta,
        memory_dir=memory_dir,
        deadline_s=deadline_s or round_deadline_s(cond, llm.deadline_s),
        history_rounds=d.HISTORY_ROUNDS if cond.history else 0,
        trace_path=trace_path,
        central=CentralBaseline(cond.baseline) if cond.baseline != "none" else None,
        activation=cond.activation,
        coordination=cond.coordination,
    )


__all__ = ["CONDITIONS", "LLM_CONDITIONS", "Condition", "round_deadline_s", "swarm_options"]
