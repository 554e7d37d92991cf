"""signal_goal: the stationary speaker tells listeners which landmark is the goal.

The goal is private: ``obs.facts["goal_landmark"]`` (a landmark id) is set for the speaker
only. The message carries the landmark's position as well when the speaker can see it.
"""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Hold, Intent, Outgoing
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import Scalar, allowed, metres, usable_id, visible

NAME = "signal_goal"
ROLES = frozenset({"speaker"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of the private goal landmark")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    goal = obs.facts.get("goal_landmark", "")
    return [Params(target_id=goal)] if usable_id(goal) and allowed(ctx, ROLES) else []


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    """Stay put and send a ``goal`` message; only the true goal is ever signalled."""
    if params.target_id != obs.facts.get("goal_landmark") or not allowed(ctx, ROLES):
        return HOLD
    body: dict[str, Scalar] = {"skill": NAME, "target_id": params.target_id}
    landmark = visible(obs, params.target_id, "landmark")
    if landmark is not None:
        body["north"], body["east"] = metres(landmark.pos[0]), metres(landmark.pos[1])
    return Intent(Hold(), messages=(Outgoing(to="*", kind="goal", body=body, purpose="task"),))
