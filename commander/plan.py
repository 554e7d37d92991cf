"""A mission plan: what the Commander publishes. Built by the harness (``commander.harness``)
from a task name (``plan_for_task``: the task's template mission, roles and top-K activation,
no LLM) or from mission text (``plan_mission``: parsing, roles and activation)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from commander.task_record import TaskRecord


@dataclass(frozen=True)
class UavAssignment:
    role: str
    local_goal: str
    skills: tuple[str, ...]


@dataclass(frozen=True)
class MissionPlan:
    mission_id: str
    task: str
    text: str
    assignments: dict[str, UavAssignment]
    constraints: tuple[str, ...] = ()
    setup_tokens: int = 0  # LLM tokens spent once on parsing, roles and activation
    notes: tuple[str, ...] = field(default_factory=tuple)
    record: TaskRecord | None = None  # the parsed task record (None for a template plan)
    parse_source: str = "template"  # "llm" | "fallback" | "template" (from the task name)
    roles_source: str = "template"  # "llm" | "template"
    catalogue: tuple[str, ...] = ()  # task-level candidate skills A^t, best first

    @property
    def participants(self) -> list[str]:
        return sorted(self.assignments)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: the task record, how it was planned, and every UAV's assignment."""
        return {
            "mission_id": self.mission_id,
            "text": self.text,
            "task": self.task,
            "record": self.record.model_dump(mode="json") if self.record is not None else None,
            "parse_source": self.parse_source,
            "roles_source": self.roles_source,
            "catalogue": list(self.catalogue),
            "assignments": {
                u: {"role": a.role, "local_goal": a.local_goal, "skills": list(a.skills)}
                for u, a in sorted(self.assignments.items())
            },
            "setup_tokens": self.setup_tokens,
            "notes": list(self.notes),
        }
