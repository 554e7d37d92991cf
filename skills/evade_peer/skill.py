"""evade_peer: fly to the point mirrored away from a visible pursuer or leader.

The escape point is ``own + max(d, escape) * unit(own - threat)``: the mirror image of the
threat through the UAV, pushed out to at least ``escape`` metres (``ctx.settings``
``evade_distance_m``, default 20) and clamped to a square of half-side ``evade_limit_m``
(default 60, inside the 63 m boundary penalty) around the arena centre
(``arena_centre_north`` / ``arena_centre_east``, default 0).
"""

from __future__ import annotations

import math

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, move_and_announce, nearest_first_k, of_kind, visible

NAME = "evade_peer"
ROLES = frozenset({"evader", "forager"})
THREAT_ROLES = frozenset({"pursuer", "leader"})
ESCAPE_M = 20.0
LIMIT_M = 60.0


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a visible pursuer or leader")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    if not allowed(ctx, ROLES):
        return []
    threats = of_kind(obs, "uav", THREAT_ROLES)
    return [Params(target_id=e.id) for e in nearest_first_k(obs, threats, ctx)]


def escape_point(
    own: tuple[float, float], threat: tuple[float, float], ctx: SkillContext
) -> tuple[float, float]:
    """North/east of the point mirrored away from ``threat``, inside the arena."""
    cn = ctx.settings.get("arena_centre_north", 0.0)
    ce = ctx.settings.get("arena_centre_east", 0.0)
    dn, de = own[0] - threat[0], own[1] - threat[1]
    d = math.hypot(dn, de)
    if d < 1e-6:  # threat on top of us: no "away"; flee toward the centre (or north there)
        dn, de = cn - own[0], ce - own[1]
        d = math.hypot(dn, de)
        if d < 1e-6:
            dn, de, d = 1.0, 0.0, 1.0
    reach = max(d, ctx.settings.get("evade_distance_m", ESCAPE_M))
    limit = ctx.settings.get("evade_limit_m", LIMIT_M)
    north = min(max(own[0] + dn / d * reach, cn - limit), cn + limit)
    east = min(max(own[1] + de / d * reach, ce - limit), ce + limit)
    return north, east


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    threat = visible(obs, params.target_id, "uav", THREAT_ROLES)
    if threat is None or not allowed(ctx, ROLES):
        return HOLD
    own = obs.own.pos
    north, east = escape_point((own[0], own[1]), (threat.pos[0], threat.pos[1]), ctx)
    return move_and_announce(NAME, threat.id, north, east, ctx)
