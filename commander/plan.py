"""A mission plan: what the Commander publishes. Built from a template for a known task
(here) or from a parsed mission (mission parsing, roles and activation)."""

from __future__ import annotations

from collections.abc import Sequence
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
    parse_source: str = "template"  # "llm" | "fallback" | "template"
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


COVERAGE_SKILLS = ("cover_landmark", "explore_local", "return_in_bounds", "hold_position")

_TEMPLATES: dict[str, tuple[str, str, str, tuple[str, ...]]] = {
    # task: (mission text, role, local goal, active skills)
    "coverage": (
        "Cover every landmark with one drone each and hold there; avoid collisions.",
        "searcher",
        "Reach a landmark no other drone is covering and stay within 3 m of it.",
        COVERAGE_SKILLS,
    ),
}


def known_tasks() -> list[str]:
    return sorted(_TEMPLATES)


def template_plan(
    task: str, uavs: Sequence[str], mission_id: str, text: str | None = None
) -> MissionPlan:
    """The fixed plan for a known task: every UAV gets the task's role and skill subset."""
    if task not in _TEMPLATES:
        raise ValueError(f"no template for task {task!r}; known: {', '.join(known_tasks())}")
    default_text, role, goal, skills = _TEMPLATES[task]
    return MissionPlan(
        mission_id=mission_id,
        task=task,
        text=text or default_text,
        assignments={u: UavAssignment(role, goal, skills) for u in uavs},
        constraints=("stay inside the 140 m x 140 m arena", "keep at least 2 m from other drones"),
    )
