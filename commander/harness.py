"""The Commander's skill harness: a task record -> ``MissionPlan`` (DESIGN §7, paper §III-A).

parse (LLM or rules) -> candidate catalogue A^t (BM25) -> roles and local goals (LLM or
template) -> per-UAV top-K activation (BM25 over Pack(q, ρ, g), + hold_position).

Three entry points, one pipeline:

* ``plan_for_task(task, uavs)``: the record comes from the task name (its template mission
  text from the task registry), roles from the task's template, activation by retrieval; no
  LLM, no tokens. What ``aeroweaver sim <task>`` flies.
* ``plan_record(parsed, ...)``: roles and activation for a record parsed earlier (the
  mission text is parsed once, before the swarm it needs is spawned).
* ``plan_mission(text, roster, ...)``: parse, then ``plan_record``.

Only parsing and role assignment call the LLM; their tokens are summed into
``setup_tokens`` once per mission (activation is retrieval, free). When the parse call fails
at the endpoint (timeout, 5xx, unreachable, breaker open), the role call is skipped rather than
spending another deadline on an endpoint that just failed.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.contracts.defaults import ARENA_HALF_M, MIN_SEPARATION_M
from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.skills import SkillRegistry, load_skills
from aeroweaver_edge.tasks import get_spec
from commander.activation import DEFAULT_CATALOGUE, DEFAULT_K, activate, task_catalogue
from commander.mission_parser import ParseOutcome, parse_mission
from commander.plan import MissionPlan, UavAssignment
from commander.retrieval import BM25Retriever
from commander.roles import RoleOutcome, assign_roles, template_roles
from commander.task_record import TaskRecord

BASE_CONSTRAINTS = (
    f"stay inside the {2 * ARENA_HALF_M:g} m x {2 * ARENA_HALF_M:g} m arena",
    f"keep at least {MIN_SEPARATION_M:g} m from other drones",
)


def _mission_id(task: str, text: str, uavs: Sequence[str]) -> str:
    digest = hashlib.sha1("\x00".join([text, *uavs]).encode()).hexdigest()[:8]
    return f"{task}-{digest}"


def _assemble(
    record: TaskRecord,
    roles: RoleOutcome,
    retriever: BM25Retriever,
    registry: SkillRegistry,
    catalogue: Sequence[str],
    k: int,
    *,
    parse: ParseOutcome | None,
    mission_id: str | None,
) -> MissionPlan:
    text = record.text
    active = activate(retriever, registry, text, record, roles.assignments, catalogue, k)
    constraints = list(record.constraints)
    if record.region is not None:
        constraints.insert(0, f"operate {record.region.describe()}")
    return MissionPlan(
        mission_id=mission_id or _mission_id(record.task, text, record.uavs),
        task=record.task,
        text=text,
        assignments={
            u: UavAssignment(a.role, a.local_goal, active[u]) for u, a in roles.assignments.items()
        },
        constraints=(*constraints, *BASE_CONSTRAINTS),
        setup_tokens=(parse.tokens if parse else 0) + roles.tokens,
        notes=(*(parse.notes if parse else ()), *roles.notes),
        record=record,
        parse_source=parse.source if parse else "template",
        roles_source=roles.source,
        catalogue=tuple(catalogue),
    )


def plan_for_task(
    task: str,
    uavs: Sequence[str],
    registry: SkillRegistry | None = None,
    k: int = DEFAULT_K,
    *,
    mission_id: str | None = None,
    catalogue_size: int = DEFAULT_CATALOGUE,
) -> MissionPlan:
    """The plan for a known task by name: its template mission text and roles, and per-role
    top-K activation by retrieval. No LLM; raises ``ValueError`` for an unknown task or a
    swarm size the task does not accept."""
    registry = registry or load_skills()
    spec = get_spec(task)
    record = TaskRecord.model_validate(
        {"task": task, "uavs": list(uavs), "text": spec.mission_text}
    )
    retriever = BM25Retriever(registry.documents())
    catalogue = task_catalogue(retriever, record, max(catalogue_size, k))
    roles = RoleOutcome(template_roles(record), "template")
    return _assemble(
        record, roles, retriever, registry, catalogue, k, parse=None, mission_id=mission_id
    )


async def plan_record(
    parsed: ParseOutcome,
    registry: SkillRegistry,
    client: ChatClient | None = None,
    k: int = DEFAULT_K,
    *,
    catalogue_size: int = DEFAULT_CATALOGUE,
    include_body: bool = False,
    mission_id: str | None = None,
) -> MissionPlan:
    """Roles (LLM or template) and activation for an already parsed mission."""
    record = parsed.record
    retriever = BM25Retriever(registry.documents(), include_body=include_body)
    catalogue = task_catalogue(retriever, record, max(catalogue_size, k))
    docs = [registry.get(n).document() for n in catalogue]
    skip = None
    if parsed.endpoint_failed and parsed.llm_error:
        skip = f"LLM skipped after the parse call failed at the endpoint ({parsed.llm_error})"
    roles = await assign_roles(record, docs, client, skip_reason=skip)
    return _assemble(
        record, roles, retriever, registry, catalogue, k, parse=parsed, mission_id=mission_id
    )


async def plan_mission(
    text: str,
    roster: Sequence[str],
    registry: SkillRegistry,
    client: ChatClient | None = None,
    k: int = DEFAULT_K,
    *,
    catalogue_size: int = DEFAULT_CATALOGUE,
    include_body: bool = False,
    mission_id: str | None = None,
) -> MissionPlan:
    """Plan a mission for the live ``roster``; raises ``MissionParseError`` if it cannot be
    understood. ``k`` task skills per UAV plus ``hold_position``."""
    parsed = await parse_mission(text, roster, client)
    return await plan_record(
        parsed,
        registry,
        client,
        k,
        catalogue_size=catalogue_size,
        include_body=include_body,
        mission_id=mission_id,
    )


async def plan_from_text(
    text: str, roster: Sequence[str], llm: LLMConfig | None, k: int = DEFAULT_K
) -> MissionPlan:
    """``plan_mission`` with the shipped skills and, if configured, an LLM endpoint; the
    client lives only for the setup calls (their tokens are counted once, here)."""
    registry = load_skills()
    if llm is None:
        return await plan_mission(text, roster, registry, None, k)
    async with ChatClient.from_config(llm) as client:
        return await plan_mission(text, roster, registry, client, k)


__all__ = ["BASE_CONSTRAINTS", "plan_for_task", "plan_from_text", "plan_mission", "plan_record"]
