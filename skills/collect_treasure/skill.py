"""collect_treasure: an empty collector flies to a visible treasure to pick it up.

Treasures are entities of kind ``"treasure"`` whose ``role`` is their colour (type). The
simulator performs the pickup (on contact, about 5 m) and reports the load in ``obs.facts["cargo"]``
(the colour, or empty); this executor never claims a pickup itself.
"""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, move_and_announce, nearest_first_k, of_kind, visible

NAME = "collect_treasure"
ROLES = frozenset({"collector"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a visible treasure")


def _empty(obs: Observation) -> bool:
    return not obs.facts.get("cargo")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    if not allowed(ctx, ROLES) or not _empty(obs):
        return []
    return [Params(target_id=e.id) for e in nearest_first_k(obs, of_kind(obs, "treasure"), ctx)]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    treasure = visible(obs, params.target_id, "treasure")
    if treasure is None or not _empty(obs) or not allowed(ctx, ROLES):
        return HOLD
    north, east = treasure.pos[0], treasure.pos[1]
    return move_and_announce(NAME, treasure.id, north, east, ctx, colour=treasure.role, cargo="")
