"""seek_food: the forager flies to a visible food source (a visit counts within 3 m)."""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, move_and_announce, of_kind, visible

NAME = "seek_food"
ROLES = frozenset({"forager"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a visible food source")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    if not allowed(ctx, ROLES):
        return []
    return [Params(target_id=e.id) for e in of_kind(obs, "food")]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    food = visible(obs, params.target_id, "food")
    if food is None or not allowed(ctx, ROLES):
        return HOLD
    return move_and_announce(NAME, food.id, food.pos[0], food.pos[1], ctx)
