"""Roles and local goals per participating UAV (paper: ρ_k, g_k).

One LLM call proposes ``{"assignments": [{"uav", "role", "local_goal"}]}``; the proposal is
accepted only if it is a complete, well-formed answer for *this* task: every participating UAV
exactly once and nobody else, role names from the task's own roles, and counts that match the
mission's stated counts and the task's bounds (one speaker, one leader, ...). Anything else
falls back to the per-task template (docs/notes/mpe-tasks.md "Default roles"), and the reason is
recorded. The template is also what runs without a client.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StringConstraints, ValidationError

from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.skills import SkillDocument
from aeroweaver_edge.tasks import get_spec
from commander.mission_parser import JsonAnswer, ask_json
from commander.task_record import TaskRecord, validation_summary

ROLES_MAX_TOKENS = 1200  # cap; the per-call budget scales with the team (see _roles_budget)
RoleSource = Literal["llm", "template"]


class RoleError(ValueError):
    """A proposed role assignment does not fit the task record."""


@dataclass(frozen=True)
class RoleAssignment:
    role: str
    local_goal: str


class _Choice(BaseModel):
    model_config = ConfigDict(extra="forbid")

    uav: Annotated[str, StringConstraints(strip_whitespace=True, min_length=1)]
    role: Annotated[str, StringConstraints(strip_whitespace=True, min_length=1)]
    local_goal: Annotated[
        str, StringConstraints(strip_whitespace=True, min_length=1, max_length=300)
    ]


class RolePlan(BaseModel):
    """What the LLM fills in."""

    model_config = ConfigDict(extra="forbid")

    assignments: list[_Choice] = Field(min_length=1)


def role_schema(record: TaskRecord) -> dict[str, Any]:
    """``RolePlan``'s schema narrowed to this record: UAV ids and role names are enums and
    the list has one entry per UAV, so a grammar-constrained server cannot invent them."""
    schema = RolePlan.model_json_schema()
    choice = schema["$defs"]["_Choice"]["properties"]
    choice["uav"] = {"enum": sorted(record.uavs)}
    choice["role"] = {"enum": list(get_spec(record.task).role_names)}
    choice["local_goal"]["maxLength"] = 160
    items = schema["properties"]["assignments"]
    items["minItems"] = items["maxItems"] = len(record.uavs)
    return schema


def _roles_budget(record: TaskRecord) -> int:
    return min(ROLES_MAX_TOKENS, 60 + 70 * len(record.uavs))


def _region_goal(record: TaskRecord) -> str:
    return f" Stay {record.region.describe()}." if record.region is not None else ""


def template_roles(record: TaskRecord) -> dict[str, RoleAssignment]:
    """Default roles for the task, honouring the role counts the mission stated."""
    spec = get_spec(record.task)
    n = len(record.uavs)
    counts = {r: c for r, c in spec.role_counts(n).items() if c > 0}
    stated = {r: c for r, c in record.role_counts.items() if r in spec.role_names}
    counts.update(stated)
    # Roles the mission did not fix absorb the difference, unbounded ones first.
    diff = n - sum(counts.values())
    for r in sorted(
        (r for r in spec.roles if r.name not in stated), key=lambda r: r.max_count is not None
    ):
        have = counts.get(r.name, 0)
        cap = n if r.max_count is None else r.max_count
        step = min(diff, cap - have) if diff > 0 else -min(-diff, have - r.min_count)
        counts[r.name] = have + step
        diff -= step
    if diff != 0:
        raise RoleError(f"no role template for {record.task} with {n} UAVs and counts {stated}")
    roles = [r.name for r in spec.roles for _ in range(counts.get(r.name, 0))]
    extra = _region_goal(record)
    return {
        uav: RoleAssignment(role, spec.role(role).goal + extra)
        for uav, role in zip(record.uavs, roles, strict=True)
    }


def check_roles(plan: RolePlan, record: TaskRecord) -> dict[str, RoleAssignment]:
    """Accept a proposal only if it fits the record; ``RoleError`` says what does not."""
    spec = get_spec(record.task)
    problems: list[str] = []
    seen = Counter(c.uav for c in plan.assignments)
    if dup := sorted(u for u, n in seen.items() if n > 1):
        problems.append(f"UAVs given more than one role: {', '.join(dup)}")
    if missing := [u for u in record.uavs if u not in seen]:
        problems.append(f"UAVs without a role: {', '.join(missing)}")
    if extra := sorted(set(seen) - set(record.uavs)):
        problems.append(f"UAVs not in the mission: {', '.join(extra)}")
    if bad := sorted({c.role for c in plan.assignments} - set(spec.role_names)):
        problems.append(
            f"roles not in {record.task}: {', '.join(bad)} (roles: {', '.join(spec.role_names)})"
        )
    counts = Counter(c.role for c in plan.assignments)
    for r in spec.roles:
        n = counts.get(r.name, 0)
        want = record.role_counts.get(r.name)
        if want is not None and n != want:
            problems.append(f"{r.name}: {n} assigned but the mission asks for {want}")
        elif n < r.min_count or (r.max_count is not None and n > r.max_count):
            hi = "n" if r.max_count is None else str(r.max_count)
            problems.append(f"{r.name}: {n} assigned, {record.task} needs {r.min_count}..{hi}")
    if problems:
        raise RoleError("; ".join(problems))
    return {c.uav: RoleAssignment(c.role, c.local_goal) for c in plan.assignments}


def role_messages(record: TaskRecord, catalogue: Sequence[SkillDocument]) -> list[dict[str, str]]:
    """The Commander context: mission, record, roles and the candidate catalogue's docs."""
    spec = get_spec(record.task)
    roles = "\n".join(
        f"- {r.name}: {r.min_count}..{'n' if r.max_count is None else r.max_count} UAVs"
        f"{', stationary' if r.stationary else ''}. Typical goal: {r.goal}"
        for r in spec.roles
    )
    skills = "\n".join(f"- {d.name}: {' '.join(d.description.split())}" for d in catalogue)
    schema = json.dumps(role_schema(record), separators=(",", ":"))
    system = (
        "You are the Commander of a UAV swarm. Give every participating UAV exactly one role "
        "of this task and a one-sentence local goal for it. Answer with exactly one JSON "
        "object matching the JSON Schema below, and nothing else.\n\n"
        f"Task: {spec.name} ({spec.summary}).\nRoles:\n{roles}\n"
        f"Played by the environment, not by our UAVs: {', '.join(spec.scripted_names) or 'none'}.\n"
        f"Skills the UAVs will choose from:\n{skills}\n\nJSON Schema: {schema}"
    )
    record_json = record.model_dump_json(exclude={"text"})
    user = f"Mission: {record.text}\nTask record: {record_json}"
    return [{"role": "system", "content": system}, {"role": "user", "content": user}]


@dataclass(frozen=True)
class RoleOutcome:
    assignments: dict[str, RoleAssignment]
    source: RoleSource
    tokens: int = 0
    notes: tuple[str, ...] = ()


async def assign_roles(
    record: TaskRecord,
    catalogue: Sequence[SkillDocument],
    client: ChatClient | None = None,
    *,
    skip_reason: str | None = None,
) -> RoleOutcome:
    """LLM roles when a client is given and no ``skip_reason``; otherwise, or when the
    proposal does not fit, the template."""
    if client is None or skip_reason is not None:
        skipped = skip_reason or "no LLM client"
        return RoleOutcome(
            template_roles(record),
            "template",
            notes=(f"roles: {skipped}; used the task's role template",),
        )
    answer: JsonAnswer = await ask_json(
        client,
        role_messages(record, catalogue),
        role_schema(record),
        name="role_plan",
        purpose="role_assign",
        max_tokens=_roles_budget(record),
    )
    why: str | None = answer.error
    if answer.data is not None:
        try:
            plan = RolePlan.model_validate(answer.data)
            return RoleOutcome(check_roles(plan, record), "llm", answer.tokens, answer.notes)
        except ValidationError as e:
            why = f"invalid role plan: {validation_summary(e)}"
        except RoleError as e:
            why = f"role plan does not fit the task: {e}"
    note = f"roles: LLM answer rejected ({why}); used the task's role template"
    return RoleOutcome(template_roles(record), "template", answer.tokens, (*answer.notes, note))


__all__ = [
    "RoleAssignment",
    "RoleError",
    "RoleOutcome",
    "RolePlan",
    "assign_roles",
    "check_roles",
    "role_messages",
    "template_roles",
]
