"""Task-level candidate catalogue and per-UAV top-K skill activation (paper Eq. 2).

* Catalogue A^t: BM25 over the whole library with the task query (mission text, the parsed
  task type and the task's role names), best ``catalogue_size`` skills.
* Per UAV k: the role-conditioned query q_k = Pack(q, ρ_k, g_k) ranks A^t; skills whose
  ``conditions`` restrict them to other roles are dropped; the best K remain and
  ``hold_position`` is always appended (K task skills + hold, as the authors' 8 + hold).

Role conditions follow the skill packages' convention, a condition line such as
``role is pursuer or leader`` (also accepted: ``roles: pursuer, leader``). Skills without one
are open to any mobile role. Stationary roles (speaker, sender, receiver) get only skills that
name their role, plus hold, because the task note gives them only their communication skills.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence

from aeroweaver_edge.contracts.defaults import CATALOGUE_SIZE, HOLD_SKILL, TOP_K
from aeroweaver_edge.skills import SkillRegistry
from aeroweaver_edge.tasks import get_spec
from commander.retrieval import BM25Retriever
from commander.roles import RoleAssignment
from commander.task_record import TaskRecord

HOLD = HOLD_SKILL
DEFAULT_K = TOP_K
DEFAULT_CATALOGUE = CATALOGUE_SIZE

_ROLE_CONDITION = re.compile(r"^\s*(?:for\s+)?roles?\s*(?:is|are|:|=)\s*(.+)$", re.IGNORECASE)
_PLACEHOLDER = re.compile(r"<[^>]*>")
_NOT_ROLES = frozenset({"or", "and", "a", "an", "the", "any", "of", "one", "either", "only"})


def condition_roles(conditions: Iterable[str]) -> frozenset[str] | None:
    """Roles named by ``role is ...`` condition lines; None when no line restricts roles.

    ``role is deposit_<colour> (deposit_red or deposit_blue)`` gives {deposit_red,
    deposit_blue} (a ``<placeholder>`` is dropped); ``roles: any`` means unrestricted.
    """
    roles: set[str] = set()
    restricted = False
    for line in conditions:
        m = _ROLE_CONDITION.match(line)
        if m is None:
            continue
        words = re.findall(r"[a-z][a-z0-9_]*", _PLACEHOLDER.sub(" ", m.group(1).lower()))
        names = {w for w in words if w not in _NOT_ROLES and not w.endswith("_")}
        if names & {"all", "everyone", "every"} or "*" in m.group(1):
            return None
        restricted = True
        roles |= names
    return frozenset(roles) if restricted else None


def role_allows(registry: SkillRegistry, skill: str, role: str, stationary: bool) -> bool:
    if skill == HOLD:
        return True
    roles = condition_roles(registry.get(skill).doc.conditions)
    if roles is None:
        return not stationary
    return role in roles


def pack(query: str, role: str, goal: str) -> str:
    """Pack(q, ρ, g): the mission text, the role and its local goal, concatenated."""
    return f"{query.strip()}\nRole: {role}\nLocal goal: {goal.strip()}"


def task_query(record: TaskRecord) -> str:
    """The task-level query: the mission text plus what the record added (task and roles)."""
    spec = get_spec(record.task)
    return f"{record.text.strip()}\nTask: {spec.name} ({spec.summary})\nRoles: " + ", ".join(
        spec.role_names
    )


def task_catalogue(
    retriever: BM25Retriever, record: TaskRecord, size: int = DEFAULT_CATALOGUE
) -> list[str]:
    """A^t: the ``size`` best skills for the task query (names, best first)."""
    return [h.name for h in retriever.rank(task_query(record), size)]


VEHICLE_ACTION_TAG = "vehicle"
"""Take-off, landing and return-home change the vehicle's state and need operator approval;
they are never activated for the LLM by task retrieval."""


def activate(
    retriever: BM25Retriever,
    registry: SkillRegistry,
    text: str,
    record: TaskRecord,
    assignments: Mapping[str, RoleAssignment],
    catalogue: Sequence[str],
    k: int = DEFAULT_K,
) -> dict[str, tuple[str, ...]]:
    """L_k per UAV: top-K of the catalogue for Pack(text, role, goal), role-filtered, + hold."""
    if k < 0:
        raise ValueError(f"k must be >= 0, got {k}")
    if HOLD not in registry:
        raise ValueError(f"the skill library has no {HOLD!r}, which every UAV must be given")
    spec = get_spec(record.task)
    out: dict[str, tuple[str, ...]] = {}
    for uav, a in assignments.items():
        stationary = a.role in spec.role_names and spec.role(a.role).stationary
        hits = retriever.rank(pack(text, a.role, a.local_goal), among=catalogue)
        chosen = [
            h.name
            for h in hits
            if h.name != HOLD
            and VEHICLE_ACTION_TAG not in registry.get(h.name).doc.tags
            and role_allows(registry, h.name, a.role, stationary)
        ][:k]
        out[uav] = (*chosen, HOLD)
    return out


FLIGHT_TAG = "flight"
"""Flight skills (take off, go to, orbit, land, return) are not task skills."""


def full_catalogue(registry: SkillRegistry) -> tuple[str, ...]:
    """Every task skill of the library (the paper's 22, ``hold_position`` last): what the
    baselines and the "without skill activation" ablation get -- no role filter, no top-K."""
    names = sorted(
        n for n in registry.names() if n != HOLD and FLIGHT_TAG not in registry.get(n).doc.tags
    )
    return (*names, HOLD)


__all__ = [
    "DEFAULT_CATALOGUE",
    "DEFAULT_K",
    "FLIGHT_TAG",
    "HOLD",
    "activate",
    "condition_roles",
    "full_catalogue",
    "pack",
    "role_allows",
    "task_catalogue",
    "task_query",
]
