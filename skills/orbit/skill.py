"""orbit: circle a centre point at a fixed radius, clockwise seen from above.

Each call aims at the point on the circle a short arc ahead of the UAV's current bearing
from the centre (``ctx.settings`` ``orbit_step_m``, default 6 m, i.e. about one round at
cruise speed), so repeated calls trace the circle. Options are the visible points of
interest (``waypoint`` / ``landmark``) with radius ``orbit_radius_m`` (default 10 m).
"""

from __future__ import annotations

import math

from pydantic import Field

from aeroweaver_edge.contracts.actions import Intent, MoveTo
from aeroweaver_edge.contracts.defaults import ARENA_HALF_M
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams

NAME = "orbit"
POINT_KINDS = ("waypoint", "landmark")
BOUND_M = ARENA_HALF_M
RADIUS_M = 10.0
MIN_RADIUS_M, MAX_RADIUS_M = 2.0, 50.0
STEP_M = 6.0


class Params(SkillParams):
    centre_north_m: float = Field(ge=-BOUND_M, le=BOUND_M, description="centre north, m")
    centre_east_m: float = Field(ge=-BOUND_M, le=BOUND_M, description="centre east, m")
    radius_m: float = Field(ge=MIN_RADIUS_M, le=MAX_RADIUS_M, description="orbit radius, m")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    if not obs.own.in_air:
        return []
    radius = ctx.settings.get("orbit_radius_m", RADIUS_M)
    if not MIN_RADIUS_M <= radius <= MAX_RADIUS_M:  # also refuses NaN
        radius = RADIUS_M
    out = []
    for e in obs.entities:
        north, east = round(e.pos[0], 1), round(e.pos[1], 1)
        if e.kind in POINT_KINDS and abs(north) <= BOUND_M and abs(east) <= BOUND_M:
            out.append(Params(centre_north_m=north, centre_east_m=east, radius_m=radius))
    return out


def next_point(params: Params, own: tuple[float, float], step_m: float) -> tuple[float, float]:
    """The point on the circle ``step_m`` of arc clockwise from the UAV's bearing."""
    cn, ce, r = params.centre_north_m, params.centre_east_m, params.radius_m
    dn, de = own[0] - cn, own[1] - ce
    bearing = math.atan2(de, dn) if math.hypot(dn, de) > 1e-6 else 0.0
    angle = bearing + min(math.pi / 2, step_m / r)
    return cn + r * math.cos(angle), ce + r * math.sin(angle)


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    own = obs.own.pos
    step = ctx.settings.get("orbit_step_m", STEP_M)
    north, east = next_point(params, (own[0], own[1]), step)
    return Intent(MoveTo((north, east, -ctx.altitude_m)))
