"""The task record χ: what the Commander understood a mission to be (paper §III-A).

One pydantic model serves three purposes: its JSON Schema is what the LLM is asked to fill,
``model_validate`` is the gate every record passes (LLM or fallback), and the validated record
is what roles and activation work from. Validation needs the live roster to check that the
participating UAVs are up, so it is passed as validation context::

    TaskRecord.model_validate(data, context={"roster": ["uav0", "uav1"]})

The task types, their roles and role-count bounds come from the task registry
(``aeroweaver_edge.tasks``): one definition per task, which the simulator reads too.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Annotated, Any, Literal

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

from aeroweaver_edge.contracts.defaults import ARENA_HALF_M, MAX_UAVS
from aeroweaver_edge.tasks import TASK_NAMES, get_spec
from aeroweaver_edge.tasks.spec import RoleSpec, TaskSpec

TASK_TYPES: tuple[str, ...] = TASK_NAMES


def task_roles(task: str) -> tuple[str, ...]:
    """Every role name of a task, ours first, then the scripted ones."""
    spec = get_spec(task)
    return (*spec.role_names, *spec.scripted_names)


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

    task: str = Field(
        description="one of the task types", json_schema_extra={"enum": list(TASK_NAMES)}
    )
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

    @field_validator("task")
    @classmethod
    def _known_task(cls, v: str) -> str:
        if v not in TASK_NAMES:
            raise ValueError(f"unknown task type {v!r} (known: {', '.join(TASK_NAMES)})")
        return v

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
        if task in TASK_NAMES:
            spec = get_spec(task)
            if not spec.min_uavs <= len(v) <= spec.max_uavs:
                raise ValueError(f"{task} needs {spec.describe_size()}, got {len(v)}")
        return v

    @field_validator("role_counts")
    @classmethod
    def _roles_of_task(cls, v: dict[str, int], info: ValidationInfo) -> dict[str, int]:
        task = info.data.get("task")
        if task not in TASK_NAMES:
            return v  # the task error is reported on its own field
        spec = get_spec(task)
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
    "TASK_TYPES",
    "BoxRegion",
    "CircleRegion",
    "Region",
    "RoleSpec",
    "TaskRecord",
    "TaskSpec",
    "task_roles",
    "validation_summary",
]
