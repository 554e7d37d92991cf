"""pursue_target: chase a visible evader or forager to a ring slot ahead of it; share it.

The aim point is the target's position predicted ``lead`` seconds ahead from its velocity,
offset by ``ring`` metres at a bearing of 120 degrees times the UAV index, so pursuers close
in from different sides instead of stacking. ``ctx.settings`` may override
``pursuit_lead_s`` (default 1.0) and ``pursuit_ring_m`` (default 3.0).
"""

from __future__ import annotations

import math

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent, MoveTo
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, of_kind, target_report, visible

NAME = "pursue_target"
ROLES = frozenset({"pursuer", "leader"})
TARGET_ROLES = frozenset({"evader", "forager"})
LEAD_S = 1.0
RING_M = 3.0


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a visible evader or forager")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    if not allowed(ctx, ROLES):
        return []
    return [Params(target_id=e.id) for e in of_kind(obs, "uav", TARGET_ROLES)]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    """Fly to the ring slot ahead of the target; send a ``target`` report to peers."""
    target = visible(obs, params.target_id, "uav", TARGET_ROLES)
    if target is None or not allowed(ctx, ROLES):
        return HOLD
    lead = ctx.settings.get("pursuit_lead_s", LEAD_S)
    ring = ctx.settings.get("pursuit_ring_m", RING_M)
    angle = 2.0 * math.pi / 3.0 * ctx.uav_index
    north = target.pos[0] + target.vel[0] * lead + ring * math.cos(angle)
    east = target.pos[1] + target.vel[1] * lead + ring * math.sin(angle)
    report = target_report(NAME, target)
    return Intent(MoveTo((north, east, -ctx.altitude_m)), messages=(report,))
