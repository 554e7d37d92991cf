"""infer_goal: the adversary flies to the visible landmark it believes is the goal."""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, move_and_announce, nearest_first_k, of_kind, visible

NAME = "infer_goal"
ROLES = frozenset({"adversary"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a visible candidate landmark")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    if not allowed(ctx, ROLES):
        return []
    return [Params(target_id=e.id) for e in nearest_first_k(obs, of_kind(obs, "landmark"), ctx)]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    landmark = visible(obs, params.target_id, "landmark")
    if landmark is None or not allowed(ctx, ROLES):
        return HOLD
    return move_and_announce(NAME, landmark.id, landmark.pos[0], landmark.pos[1], ctx)
