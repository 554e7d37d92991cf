"""signal_target: the leader hovers and reports a visible forager/evader to its team."""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Hold, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, of_kind, target_report, visible

NAME = "signal_target"
ROLES = frozenset({"leader"})
TARGET_ROLES = frozenset({"evader", "forager"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a visible forager or evader")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    if not allowed(ctx, ROLES):
        return []
    return [Params(target_id=e.id) for e in of_kind(obs, "uav", TARGET_ROLES)]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    """Zero velocity and a ``target`` message with the target's position and velocity."""
    target = visible(obs, params.target_id, "uav", TARGET_ROLES)
    if target is None or not allowed(ctx, ROLES):
        return HOLD
    report = target_report(NAME, target)
    return Intent(Hold(), messages=(report,))
