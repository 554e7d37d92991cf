"""cover_landmark: fly over a visible landmark and announce it to reachable peers."""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent, MoveTo, Outgoing
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import metres, nearest_first_k

NAME = "cover_landmark"


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a landmark visible now")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    """One option per landmark in sensing range (the nearest eight when more are in view)."""
    return [Params(target_id=e.id) for e in nearest_first_k(obs, obs.of_kind("landmark"), ctx)]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    """Move to the landmark at the fixed altitude; hold if it is no longer visible."""
    landmark = obs.entity(params.target_id)
    if landmark is None or landmark.kind != "landmark":
        return HOLD
    north, east = landmark.pos[0], landmark.pos[1]
    announce = Outgoing(
        to="*",
        kind="intent",
        body={
            "skill": NAME,
            "target_id": landmark.id,
            "north": metres(north),
            "east": metres(east),
        },
    )
    return Intent(MoveTo((north, east, -ctx.altitude_m)), messages=(announce,))
