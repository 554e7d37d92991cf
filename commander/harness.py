"""The Commander's skill harness: mission text -> ``MissionPlan`` (DESIGN §7, paper §III-A).

parse (LLM or rules) -> candidate catalogue A^t (BM25) -> roles and local goals (LLM or
template) -> per-UAV top-K activation (BM25 over Pack(q, ρ, g), + hold_position).

Only parsing and role assignment call the LLM; their tokens are summed into
``setup_tokens`` once per mission (activation is retrieval, free). When the parse call fails
at the endpoint (timeout, 5xx, unreachable, breaker open), the role call is skipped rather than
spending another deadline on an endpoint that just failed.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.skills import SkillRegistry, load_skills
from commander.activation import DEFAULT_CATALOGUE, DEFAULT_K, activate, task_catalogue
from commander.mission_parser import parse_mission
from commander.plan import MissionPlan, UavAssignment
from commander.retrieval import BM25Retriever
from commander.roles import assign_roles

BASE_CONSTRAINTS = ("stay inside the 140 m x 140 m arena", "keep at least 2 m from other drones")


def _mission_id(task: str, text: str, uavs: Sequence[str]) -> str:
    digest = hashlib.sha1("\x00".join([text, *uavs]).encode()).hexdigest()[:8]
    return f"{task}-{digest}"


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
    record = parsed.record
    retriever = BM25Retriever(registry.documents(), include_body=include_body)
    catalogue = task_catalogue(retriever, record, max(catalogue_size, k))
    docs = [registry.get(n).document() for n in catalogue]
    skip = None
    if parsed.endpoint_failed and parsed.llm_error:
        skip = f"LLM skipped after the parse call failed at the endpoint ({parsed.llm_error})"
    roles = await assign_roles(record, docs, client, skip_reason=skip)
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
        setup_tokens=parsed.tokens + roles.tokens,
        notes=(*parsed.notes, *roles.notes),
        record=record,
        parse_source=parsed.source,
        roles_source=roles.source,
        catalogue=tuple(catalogue),
    )


__all__ = ["plan_mission"]


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
