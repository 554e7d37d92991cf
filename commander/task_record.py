"""The task record χ: what the Commander understood a mission to be (paper §III-A).

One pydantic model serves three purposes: its JSON Schema is what the LLM is asked to fill,
``model_validate`` is the gate every record passes (LLM or fallback), and the validated record
is what roles and activation work from. Validation needs the live roster to check that the
participating UAVs are up, so it is passed as validation context::

    TaskRecord.model_validate(data, context={"roster": ["uav0", "uav1"]})

The nine task types, their roles and role-count bounds live here too (``TASKS``), because the
record's own validation depends on them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, Literal, get_args

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StringConstraints,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

ARENA_HALF_M = 70.0  # the arena is north/east in [-70, 70] m around the local origin
MAX_UAVS = 10  # at most 10 UAVs per task (notes/mpe-tasks.md)

TaskType = Literal[
    "coverage",
    "pursuit_evasion",
    "guided_navigation",
    "private_communication",
    "circular_formation",
    "line_formation",
    "world_communication",
    "collection_delivery",
    "goal_concealment",
]
TASK_TYPES: tuple[str, ...] = get_args(TaskType)


# --------------------------------------------------------------------------- task specs


@dataclass(frozen=True)
class RoleSpec:
    """A role a UAV of this swarm may take, with bounds on how many UAVs take it."""

    name: str
    min_count: int
    max_count: int | None  # None: unbounded
    goal: str  # template local goal
    stationary: bool = False  # stationary roles get only non-actuating skills plus hold


@dataclass(frozen=True)
class TaskSpec:
    name: str
    summary: str
    roles: tuple[RoleSpec, ...]  # roles our UAVs play
    scripted: tuple[str, ...]  # roles the environment plays (may appear in role_counts)
    defaults: Callable[[int], dict[str, int]]  # template role counts for n UAVs
    team_size: int  # UAVs used when the mission states no number (the note's default roles)

    def role(self, name: str) -> RoleSpec:
        return next(r for r in self.roles if r.name == name)

    @property
    def role_names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.roles)

    @property
    def min_uavs(self) -> int:
        return max(1, sum(r.min_count for r in self.roles))

    @property
    def max_uavs(self) -> int:
        if any(r.max_count is None for r in self.roles):
            return MAX_UAVS
        return min(MAX_UAVS, sum(r.max_count or 0 for r in self.roles))

    def describe_size(self) -> str:
        lo, hi = self.min_uavs, self.max_uavs
        roles = ", ".join(self.role_names)
        if lo == hi:
            return f"exactly {lo} UAVs ({roles})"
        return f"{lo} to {hi} UAVs ({roles})"


def _all(role: str) -> Callable[[int], dict[str, int]]:
    return lambda n: {role: n}


def _one_plus(first: str, rest: str) -> Callable[[int], dict[str, int]]:
    return lambda n: {first: 1, rest: n - 1}


def _collection(n: int) -> dict[str, int]:
    # Two mobile deposits only when at least two collectors remain (the default: 2 + 2).
    if n >= 4:
        return {"collector": n - 2, "deposit_red": 1, "deposit_blue": 1}
    return {"collector": n}


TASKS: dict[str, TaskSpec] = {
    s.name: s
    for s in (
        TaskSpec(
            "coverage",
            "cover every landmark with one UAV each",
            (
                RoleSpec(
                    "searcher",
                    1,
                    None,
                    "Reach a landmark no other drone is covering and stay within 3 m of it.",
                ),
            ),
            (),
            _all("searcher"),
            3,
        ),
        TaskSpec(
            "pursuit_evasion",
            "pursuers catch an evading drone",
            (
                RoleSpec(
                    "pursuer",
                    1,
                    None,
                    "Close in on the evader with the other pursuers until "
                    "at least two of you are within 6 m of it; share where it is.",
                ),
            ),
            ("evader",),
            _all("pursuer"),
            3,
        ),
        TaskSpec(
            "guided_navigation",
            "a stationary speaker guides listeners to a goal landmark",
            (
                RoleSpec(
                    "speaker",
                    1,
                    1,
                    "Tell the listeners which landmark is the goal; stay where you are.",
                    stationary=True,
                ),
                RoleSpec(
                    "listener",
                    1,
                    None,
                    "Follow the speaker's signal to the goal landmark and stop within 3 m of it.",
                ),
            ),
            (),
            _one_plus("speaker", "listener"),
            2,
        ),
        TaskSpec(
            "private_communication",
            "a sender passes an encrypted symbol to a receiver past an eavesdropper",
            (
                RoleSpec(
                    "sender",
                    1,
                    1,
                    "Encrypt the private symbol with the shared key and send "
                    "the ciphertext to the receiver; stay where you are.",
                    stationary=True,
                ),
                RoleSpec(
                    "receiver",
                    1,
                    1,
                    "Decode the sender's ciphertext with the shared key and "
                    "record the right symbol; stay where you are.",
                    stationary=True,
                ),
            ),
            ("eavesdropper",),
            lambda n: {"sender": 1, "receiver": 1},
            2,
        ),
        TaskSpec(
            "circular_formation",
            "members form a circle around a centre marker",
            (
                RoleSpec(
                    "member",
                    2,
                    None,
                    "Take your own slot on the circle around the centre "
                    "marker and hold within 3 m of it.",
                ),
            ),
            (),
            _all("member"),
            5,
        ),
        TaskSpec(
            "line_formation",
            "members form an evenly spaced line between two endpoints",
            (
                RoleSpec(
                    "member",
                    2,
                    None,
                    "Take your own slot on the line between the two "
                    "endpoints and hold within 3 m of it.",
                ),
            ),
            (),
            _all("member"),
            5,
        ),
        TaskSpec(
            "world_communication",
            "a leader signals foragers' positions to pursuers who catch them",
            (
                RoleSpec(
                    "leader",
                    1,
                    1,
                    "Spot foragers with your long-range sensor, signal their "
                    "positions to the pursuers and chase the nearest one.",
                ),
                RoleSpec(
                    "pursuer",
                    0,
                    None,
                    "Catch foragers, following the leader's target "
                    "messages when they are out of sight or hidden in a forest.",
                ),
            ),
            ("forager",),
            _one_plus("leader", "pursuer"),
            3,
        ),
        TaskSpec(
            "collection_delivery",
            "collectors pick up treasures and deliver them to the matching deposit",
            (
                RoleSpec(
                    "collector",
                    1,
                    None,
                    "Pick up an available treasure and deliver it to "
                    "the deposit of its colour; avoid crowding other collectors.",
                ),
                RoleSpec(
                    "deposit_red",
                    0,
                    1,
                    "Move toward collectors carrying red treasure to take their delivery.",
                ),
                RoleSpec(
                    "deposit_blue",
                    0,
                    1,
                    "Move toward collectors carrying blue treasure to take their delivery.",
                ),
            ),
            (),
            _collection,
            4,
        ),
        TaskSpec(
            "goal_concealment",
            "informed UAVs reach the goal landmark without revealing it to an adversary",
            (
                RoleSpec(
                    "informed",
                    1,
                    None,
                    "Keep a drone on the goal landmark while others "
                    "visit decoy landmarks so the adversary cannot tell which is the goal.",
                ),
            ),
            ("adversary",),
            _all("informed"),
            2,
        ),
    )
}
assert tuple(TASKS) == TASK_TYPES


def task_roles(task: str) -> tuple[str, ...]:
    """Every role name of a task, ours first, then the scripted ones."""
    spec = TASKS[task]
    return (*spec.role_names, *spec.scripted)


# --------------------------------------------------------------------------- regions

_Coord = Annotated[float, Field(ge=-ARENA_HALF_M, le=ARENA_HALF_M)]


class CircleRegion(BaseModel):
    """A disc: centre north/east and radius, metres in the arena frame."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    kind: Literal["circle"] = "circle"
    north_m: _Coord
    east_m: _Coord
    radius_m: float = Field(gt=0, le=2 * ARENA_HALF_M)

    def describe(self) -> str:
        return f"within {self.radius_m:g} m of north {self.north_m:g} m, east {self.east_m:g} m"


class BoxRegion(BaseModel):
    """An axis-aligned box in the arena frame, metres."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    kind: Literal["box"] = "box"
    north_min_m: _Coord
    north_max_m: _Coord
    east_min_m: _Coord
    east_max_m: _Coord

    @model_validator(mode="after")
    def _ordered(self) -> BoxRegion:
        if self.north_min_m >= self.north_max_m or self.east_min_m >= self.east_max_m:
            raise ValueError("box needs north_min_m < north_max_m and east_min_m < east_max_m")
        return self

    def describe(self) -> str:
        return (
            f"inside the box north {self.north_min_m:g}..{self.north_max_m:g} m, "
            f"east {self.east_min_m:g}..{self.east_max_m:g} m"
        )


Region = Annotated[CircleRegion | BoxRegion, Field(discriminator="kind")]

_Text = Annotated[str, StringConstraints(strip_whitespace=True, min_length=1, max_length=300)]


# --------------------------------------------------------------------------- the record


class TaskRecord(BaseModel):
    """Task type, participating UAVs, role counts, region and constraints of one mission."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    task: TaskType = Field(description="one of the nine task types")
    uavs: tuple[str, ...] = Field(
        min_length=1, description="ids of the participating UAVs, a subset of the live roster"
    )
    role_counts: dict[str, Annotated[int, Field(ge=0, le=MAX_UAVS)]] = Field(
        default_factory=dict,
        description="how many UAVs take each role, only where the mission states it",
    )
    region: Region | None = Field(
        default=None, description="operating region in metres (north/east, arena ±70 m)"
    )
    constraints: tuple[_Text, ...] = Field(
        default=(), description="mission constraints stated in the text, one per item"
    )
    text: str = Field(default="", description="the original mission text")

    @field_validator("uavs")
    @classmethod
    def _uavs_up_and_sized(cls, v: tuple[str, ...], info: ValidationInfo) -> tuple[str, ...]:
        if len(set(v)) != len(v):
            raise ValueError(f"duplicate UAV ids in {list(v)}")
        roster = (info.context or {}).get("roster") if isinstance(info.context, Mapping) else None
        if roster is not None:
            down = [u for u in v if u not in set(roster)]
            if down:
                raise ValueError(
                    f"{', '.join(down)} not in the live roster ({', '.join(roster) or 'empty'})"
                )
        task = info.data.get("task")
        if task in TASKS:
            spec = TASKS[task]
            if not spec.min_uavs <= len(v) <= spec.max_uavs:
                raise ValueError(f"{task} needs {spec.describe_size()}, got {len(v)}")
        return v

    @field_validator("role_counts")
    @classmethod
    def _roles_of_task(cls, v: dict[str, int], info: ValidationInfo) -> dict[str, int]:
        task = info.data.get("task")
        if task not in TASKS:
            return v  # the task error is reported on its own field
        spec = TASKS[task]
        unknown = [r for r in v if r not in task_roles(task)]
        if unknown:
            raise ValueError(
                f"{', '.join(map(repr, unknown))} not a role of {task} "
                f"(roles: {', '.join(task_roles(task))})"
            )
        for r in spec.roles:
            n = v.get(r.name)
            if n is not None and (n < r.min_count or (r.max_count is not None and n > r.max_count)):
                cap = "any number" if r.max_count is None else str(r.max_count)
                raise ValueError(f"{r.name}: {n} is outside {r.min_count}..{cap} for {task}")
        uavs = info.data.get("uavs")
        if uavs is not None:
            ours = {r: n for r, n in v.items() if r in spec.role_names}
            rest = [r for r in spec.roles if r.name not in ours]
            lo = sum(ours.values()) + sum(r.min_count for r in rest)
            caps = [r.max_count for r in rest]
            hi = None if None in caps else sum(ours.values()) + sum(c or 0 for c in caps)
            if len(uavs) < lo or (hi is not None and len(uavs) > hi):
                need = f"{lo}" if hi == lo else f"at least {lo}" if hi is None else f"{lo}..{hi}"
                raise ValueError(f"role counts {ours} need {need} UAVs but {len(uavs)} take part")
        return v

    @classmethod
    def llm_schema(cls, roster: Sequence[str] | None = None) -> dict[str, Any]:
        """The JSON Schema the LLM fills: everything but ``text`` (we keep the original).

        With a roster, UAV ids are an enum of the live ones and the list is bounded: servers
        that compile the schema into a grammar (llama.cpp, vLLM) then cannot let a small
        model ramble through invented ids until ``max_tokens``.
        """
        schema = cls.model_json_schema()
        schema["properties"].pop("text", None)
        if "required" in schema:
            schema["required"] = [f for f in schema["required"] if f != "text"]
        if roster:
            uavs = schema["properties"]["uavs"]
            uavs["items"] = {"enum": sorted(roster)}
            uavs["uniqueItems"] = True
            uavs["maxItems"] = len(roster)
        return schema


def validation_summary(e: ValidationError) -> str:
    """``field 'uavs': ...; field 'region.radius_m': ...``: short and naming each field."""
    parts = []
    for err in e.errors():
        loc = ".".join(str(x) for x in err["loc"] if str(x) not in ("circle", "box"))
        msg = "unknown field" if err["type"] == "extra_forbidden" else err["msg"]
        msg = msg.removeprefix("Value error, ")
        parts.append(f"field '{loc or '<record>'}': {msg}")
    return "; ".join(parts)


__all__ = [
    "ARENA_HALF_M",
    "MAX_UAVS",
    "TASKS",
    "TASK_TYPES",
    "BoxRegion",
    "CircleRegion",
    "Region",
    "RoleSpec",
    "TaskRecord",
    "TaskSpec",
    "TaskType",
    "task_roles",
    "validation_summary",
]
