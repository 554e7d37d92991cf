"""What the benchmark's conditions change in a simulated run (kept out of ``swarm.py``).

* ``with_full_catalogue``: every UAV gets the whole task-skill catalogue (the baselines and
  the "without skill activation" ablation): no role filter, no top-K.
* ``with_seeded_order``: each UAV's skills in a seeded order per (task, seed, UAV) that every
  condition shares for the skills they have in common, so option labels (A, B, ...) do not
  follow the alphabet under one condition and the activation rank under another.
* ``add_central``: a baseline's central-node tokens and calls join the run's totals, with
  the split kept in ``tokens_by_side`` (the UAVs' own calls vs the central node's).
* ``WIDE_SLOT_CTX``: the embedded server's context per cache slot when prompts carry all
  22 skill documents (~2,300 tokens on their own).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any, Final

from commander.plan import MissionPlan, UavAssignment

if TYPE_CHECKING:
    from aeroweaver_edge.orchestration.swarm import RunSummary

WIDE_SLOT_CTX: Final = 4096


def with_full_catalogue(plan: MissionPlan) -> MissionPlan:
    from aeroweaver_edge.skills import load_skills
    from commander.activation import full_catalogue

    skills = full_catalogue(load_skills())
    return replace(
        plan,
        assignments={
            u: UavAssignment(a.role, a.local_goal, skills) for u, a in plan.assignments.items()
        },
        catalogue=skills,
    )


def with_seeded_order(plan: MissionPlan, seed: int) -> MissionPlan:
    """Every UAV's skill list (hence its option letters) in the order of
    ``agent.candidates.seeded_order`` keyed by (task, seed, UAV); the plan is recorded in the
    trace header, and each decision's lettered options in its round line."""
    from aeroweaver_edge.agent.candidates import seeded_order

    return replace(
        plan,
        assignments={
            u: replace(a, skills=tuple(seeded_order(a.skills, f"{plan.task}|{seed}|{u}")))
            for u, a in plan.assignments.items()
        },
    )


def add_central(summary: RunSummary, central: dict[str, Any]) -> None:
    """Fold the central node's tokens and calls into ``summary`` (totals and per episode)."""
    uav_side = dict(summary.tokens)
    ct = central["tokens"]
    summary.tokens_by_side = {"uavs": uav_side, "central": dict(ct)}
    summary.tokens = {k: uav_side.get(k, 0) + ct.get(k, 0) for k in uav_side}
    summary.llm_calls += central["llm_calls"]
    calls = summary.llm_calls
    if calls:
        t = summary.tokens
        summary.tokens_per_decision = {
            "prompt": round(t["prompt"] / calls, 1),
            "prompt_cached": round(t["prompt_cached"] / calls, 1),
            "prompt_uncached": round((t["prompt"] - t["prompt_cached"]) / calls, 1),
            "completion": round(t["completion"] / calls, 2),
        }
    for e in summary.episodes:
        e["tokens"] += central["by_episode"].get(str(e["episode"]), {}).get("tokens", 0)


__all__ = ["WIDE_SLOT_CTX", "add_central", "with_full_catalogue", "with_seeded_order"]
