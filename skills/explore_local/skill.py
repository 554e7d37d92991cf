"""explore_local: sweep a 35 m circle around the arena centre, spread out by UAV index.

The bearing is ``round / 18 + 1.7 * uav_index`` radians (the authors' rule), measured from
north toward east. ``ctx.settings`` may override ``arena_centre_north``,
``arena_centre_east`` and ``explore_radius_m`` for arenas not centred on the origin.
"""

from __future__ import annotations

import math

from aeroweaver_edge.contracts.actions import Intent, MoveTo, Outgoing
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import Scalar, metres

NAME = "explore_local"
RADIUS_M = 35.0


class Params(SkillParams):
    """No parameters: the waypoint follows from the round and the UAV's index."""


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    return [Params()]


def waypoint(round_: int, uav_index: int, ctx: SkillContext) -> tuple[float, float]:
    """North/east of this round's exploration waypoint."""
    angle = round_ / 18 + 1.7 * uav_index
    radius = ctx.settings.get("explore_radius_m", RADIUS_M)
    north = ctx.settings.get("arena_centre_north", 0.0) + radius * math.cos(angle)
    east = ctx.settings.get("arena_centre_east", 0.0) + radius * math.sin(angle)
    return north, east


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    north, east = waypoint(obs.round, ctx.uav_index, ctx)
    body: dict[str, Scalar] = {"skill": NAME, "north": metres(north), "east": metres(east)}
    announce = Outgoing(to="*", kind="intent", body=body)
    return Intent(MoveTo((north, east, -ctx.altitude_m)), messages=(announce,))
