"""The plan a simulated run flies, decided before its daemons exist.

* From a task name: ``commander.harness.plan_for_task`` (the task's template mission text,
  roles and per-role top-K activation; no LLM).
* From mission text: parsed **once**, against the UAV ids the run could spawn (``--uavs`` or
  the 50-UAV cap), with the LLM when one is configured; the record says how many UAVs and
  which task, and only those daemons are then started. Roles and activation follow.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Final

from pydantic import ValidationError

from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.contracts.defaults import MAX_UAVS, TOP_K
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.tasks import TASK_NAMES, get_spec
from aeroweaver_edge.tasks.base import uav_id
from commander.harness import plan_for_task, plan_record
from commander.mission_parser import MissionParseError, parse_mission
from commander.plan import MissionPlan, UavAssignment
from commander.task_record import validation_summary


class PlanError(UserError):
    """The run cannot be planned as asked (unknown task, a size the task does not take)."""


def uav_ids(n: int) -> list[str]:
    return [uav_id(i) for i in range(n)]


def natural(uav: str) -> tuple[str, int]:
    """Sort key: ``uav2`` before ``uav10``."""
    head = uav.rstrip("0123456789")
    tail = uav[len(head) :]
    return head, int(tail) if tail else -1


async def plan_run(
    *,
    task: str | None,
    uavs: int | None,
    mission_text: str | None,
    llm: LLMConfig | None,
    top_k: int = TOP_K,
    mission_id: str | None = None,
) -> MissionPlan:
    """The run's plan; ``PlanError``/``MissionParseError`` name what does not fit."""
    if task is not None and task not in TASK_NAMES:
        raise PlanError(f"unknown task {task!r}; known: {', '.join(TASK_NAMES)}")
    if uavs is not None and not 1 <= uavs <= MAX_UAVS:
        raise PlanError(f"the swarm size must be 1..{MAX_UAVS} UAVs, got {uavs}")
    if mission_text is None:
        name = task or "coverage"
        spec = get_spec(name)
        n = uavs if uavs is not None else spec.team_size
        if not spec.size_ok(n):
            raise PlanError(f"{name} needs {spec.describe_size()}, got {n}")
        try:
            return plan_for_task(name, uav_ids(n), k=top_k, mission_id=mission_id)
        except ValidationError as e:
            raise PlanError(f"{name} with {n} UAVs: {validation_summary(e)}") from None
    roster = uav_ids(uavs or MAX_UAVS)
    from aeroweaver_edge.skills import load_skills

    registry = load_skills()
    if llm is None:
        parsed = await parse_mission(mission_text, roster, None)
        plan = await plan_record(parsed, registry, None, top_k, mission_id=mission_id)
    else:
        from aeroweaver_edge.llm.client import ChatClient

        async with ChatClient.from_config(llm) as client:
            parsed = await parse_mission(mission_text, roster, client)
            plan = await plan_record(parsed, registry, client, top_k, mission_id=mission_id)
    if task is not None and plan.task != task:
        raise MissionParseError(
            f"the mission reads as a {plan.task} mission, but the run was asked for {task}"
        )
    return plan


WIDE_SLOT_CTX: Final = 4096
"""The embedded server's context per cache slot when prompts carry all 22 skill documents
(~2,300 tokens on their own): the full catalogue, and a central node's prompts."""


def with_full_catalogue(plan: MissionPlan) -> MissionPlan:
    """Every UAV gets the whole task-skill catalogue: no role filter, no top-K (the
    baselines and the "without skill activation" ablation)."""
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
    ``agent.candidates.seeded_order`` keyed by (task, seed, UAV), the same for every
    condition that shares a skill, so option labels follow neither the alphabet nor the
    activation rank; the plan is recorded in the trace header, and each decision's
    lettered options in its round line."""
    from aeroweaver_edge.agent.candidates import seeded_order

    return replace(
        plan,
        assignments={
            u: replace(a, skills=tuple(seeded_order(a.skills, f"{plan.task}|{seed}|{u}")))
            for u, a in plan.assignments.items()
        },
    )


__all__ = [
    "WIDE_SLOT_CTX",
    "PlanError",
    "natural",
    "plan_run",
    "uav_ids",
    "with_full_catalogue",
    "with_seeded_order",
]
