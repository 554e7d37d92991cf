"""approach_decoy: an informed agent flies to a visible landmark that is NOT the goal,
to mislead the adversary. Needs ``obs.facts["goal_landmark"]`` to know what to avoid."""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, move_and_announce, nearest_first_k, of_kind, visible

NAME = "approach_decoy"
ROLES = frozenset({"informed"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a visible non-goal landmark")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    goal = obs.facts.get("goal_landmark", "")
    if not goal or not allowed(ctx, ROLES):
        return []
    decoys = [e for e in of_kind(obs, "landmark") if e.id != goal]
    return [Params(target_id=e.id) for e in nearest_first_k(obs, decoys, ctx)]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    goal = obs.facts.get("goal_landmark", "")
    landmark = visible(obs, params.target_id, "landmark")
    if landmark is None or not goal or landmark.id == goal or not allowed(ctx, ROLES):
        return HOLD
    return move_and_announce(NAME, landmark.id, landmark.pos[0], landmark.pos[1], ctx)
