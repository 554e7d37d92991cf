"""follow_signal: the listener flies to the landmark named in a received ``goal`` message.

The landmark's visible position is used; if it is out of sensing range the position the
speaker put in the message is used instead; with neither, the UAV holds.
"""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, latest_by_target, move_and_announce, point, visible

NAME = "follow_signal"
ROLES = frozenset({"listener"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="landmark named in a received goal message")


def _destination(obs: Observation, target_id: str) -> tuple[float, float] | None:
    """Where the signalled landmark is: seen now, else as reported, else unknown."""
    msg = latest_by_target(obs, "goal").get(target_id)
    if msg is None:
        return None
    landmark = visible(obs, target_id, "landmark")
    return (landmark.pos[0], landmark.pos[1]) if landmark is not None else point(msg.body)


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    """One option per signalled landmark whose position is known (seen or reported)."""
    if not allowed(ctx, ROLES):
        return []
    goals = latest_by_target(obs, "goal")
    return [Params(target_id=t) for t in goals if _destination(obs, t) is not None]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    where = _destination(obs, params.target_id)
    if where is None or not allowed(ctx, ROLES):
        return HOLD
    return move_and_announce(NAME, params.target_id, where[0], where[1], ctx)
