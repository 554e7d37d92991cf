"""go_to: fly to a north/east point of the local frame, optionally at a given altitude.

Options are the visible points of interest (entities of kind ``waypoint`` or ``landmark``,
rounded to 0.1 m); a mission may also invoke it with any in-bounds coordinates.
"""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import Intent, MoveTo
from aeroweaver_edge.contracts.defaults import ARENA_HALF_M
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams

NAME = "go_to"
POINT_KINDS = ("waypoint", "landmark")
BOUND_M = ARENA_HALF_M


class Params(SkillParams):
    north_m: float = Field(ge=-BOUND_M, le=BOUND_M, description="north of the local origin, m")
    east_m: float = Field(ge=-BOUND_M, le=BOUND_M, description="east of the local origin, m")
    altitude_m: float | None = Field(
        default=None, ge=2.0, le=60.0, description="height in m (default: mission level)"
    )


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    if not obs.own.in_air:
        return []
    out = []
    for e in obs.entities:
        north, east = round(e.pos[0], 1), round(e.pos[1], 1)
        if e.kind in POINT_KINDS and abs(north) <= BOUND_M and abs(east) <= BOUND_M:
            out.append(Params(north_m=north, east_m=east))
    return out


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    altitude = ctx.altitude_m if params.altitude_m is None else params.altitude_m
    return Intent(MoveTo((params.north_m, params.east_m, -altitude)))
