"""seek_cover: the forager flies to the centre of a visible forest to hide in it."""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, move_and_announce, of_kind, visible

NAME = "seek_cover"
ROLES = frozenset({"forager"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a visible forest")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    if not allowed(ctx, ROLES):
        return []
    return [Params(target_id=e.id) for e in of_kind(obs, "forest")]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    forest = visible(obs, params.target_id, "forest")
    if forest is None or not allowed(ctx, ROLES):
        return HOLD
    return move_and_announce(NAME, forest.id, forest.pos[0], forest.pos[1], ctx)
