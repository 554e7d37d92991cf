"""The task registry: the nine benchmark tasks, one module each (like mpe2's scenarios).

Each module ``aeroweaver_edge.tasks.<name>`` defines ``SPEC`` (a ``TaskSpec``: what the
Commander reads) and ``TASK`` (a ``TaskDefinition`` subclass: what the simulator runs, with
its scripted reference policy). The Commander, the planner, the scripted selector and the
simulator all look tasks up here; nothing about a task is written anywhere else. Adding a
task is one new module plus its name below.

Modules are imported on first use, so a daemon that needs one task's reference policy does
not import the other eight, and nothing here imports numpy or mpe2 up front.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Mapping
from typing import Any

from aeroweaver_edge.tasks.base import TaskDefinition
from aeroweaver_edge.tasks.spec import RoleSpec, TaskSpec

TASK_NAMES: tuple[str, ...] = (
    "coverage",
    "pursuit_evasion",
    "guided_navigation",
    "private_communication",
    "circular_formation",
    "line_formation",
    "world_communication",
    "collection_delivery",
    "goal_concealment",
)
"""CLI and Commander task names, in the paper's order."""


MPE_NAMES: dict[str, str] = {
    "simple_spread": "coverage",
    "simple_tag": "pursuit_evasion",
    "simple_speaker_listener": "guided_navigation",
    "simple_crypto": "private_communication",
    "simple_formation": "circular_formation",
    "simple_line": "line_formation",
    "simple_world_comm": "world_communication",
    "collect_treasure": "collection_delivery",
    "simple_adversary": "goal_concealment",
}
"""The mpe2 scenario each task follows (its ``SPEC.mpe_module``; a test keeps them equal),
so a user may name a task the way MPE does."""


def canonical_task(text: str) -> str:
    """``TASK_NAMES`` spelling of a task a user typed: case, ``-`` or spaces for ``_``
    (``Pursuit-Evasion``) and mpe2 scenario names (``simple_spread_v3``) are accepted; anything
    else comes back unchanged, for the caller's "unknown task" error to name."""
    key = re.sub(r"[\s\-]+", "_", text.strip().lower())
    key = re.sub(r"_v\d+$", "", key) if key.startswith(("simple_", "collect_")) else key
    if key in TASK_NAMES:
        return key
    return MPE_NAMES.get(key, text)


class UnknownTask(ValueError):
    """A task name that is not one of ``TASK_NAMES``."""


def _module(name: str) -> Any:
    if name not in TASK_NAMES:
        raise UnknownTask(f"unknown task {name!r}; known: {', '.join(TASK_NAMES)}")
    return importlib.import_module(f"aeroweaver_edge.tasks.{name}")


def get_spec(name: str) -> TaskSpec:
    spec: TaskSpec = _module(name).SPEC
    return spec


def definition(name: str) -> type[TaskDefinition]:
    cls: type[TaskDefinition] = _module(name).TASK
    return cls


def specs() -> dict[str, TaskSpec]:
    """Every task's spec, in ``TASK_NAMES`` order."""
    return {n: get_spec(n) for n in TASK_NAMES}


def create(
    name: str,
    roles: Mapping[str, str] | int | None = None,
    *,
    max_rounds: int | None = None,
    altitude_m: float | None = None,
) -> TaskDefinition:
    """A task definition for ``roles`` (uav -> role), ``n`` UAVs with the template roles,
    or the task's default team (``None``)."""
    kwargs: dict[str, Any] = {"max_rounds": max_rounds}
    if altitude_m is not None:
        kwargs["altitude_m"] = altitude_m
    return definition(name)(roles, **kwargs)


__all__ = [
    "TASK_NAMES",
    "RoleSpec",
    "TaskDefinition",
    "TaskSpec",
    "UnknownTask",
    "create",
    "definition",
    "get_spec",
    "specs",
]
