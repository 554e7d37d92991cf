"""approach_goal: an informed agent flies to the private goal landmark
(``obs.facts["goal_landmark"]``)."""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, move_and_announce, usable_id, visible

NAME = "approach_goal"
ROLES = frozenset({"informed"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of the private goal landmark")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    goal = obs.facts.get("goal_landmark", "")
    if not usable_id(goal) or not allowed(ctx, ROLES) or visible(obs, goal, "landmark") is None:
        return []
    return [Params(target_id=goal)]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    landmark = visible(obs, params.target_id, "landmark")
    is_goal = params.target_id == obs.facts.get("goal_landmark")
    if landmark is None or not is_goal or not allowed(ctx, ROLES):
        return HOLD
    return move_and_announce(NAME, landmark.id, landmark.pos[0], landmark.pos[1], ctx)
