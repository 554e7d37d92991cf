"""follow_peer: fly to the position a peer reported for a target in a ``target`` message."""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, latest_by_target, move_and_announce, point

NAME = "follow_peer"
ROLES = frozenset({"pursuer"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="target named in a received target message")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    """One option per target reported (with a usable position) in received messages."""
    if not allowed(ctx, ROLES):
        return []
    reports = latest_by_target(obs, "target")
    return [Params(target_id=t) for t, m in reports.items() if point(m.body) is not None]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    """Move to the newest reported position of the target; hold if there is none."""
    msg = latest_by_target(obs, "target").get(params.target_id)
    where = None if msg is None else point(msg.body)
    if where is None or not allowed(ctx, ROLES):
        return HOLD
    return move_and_announce(NAME, params.target_id, where[0], where[1], ctx)
