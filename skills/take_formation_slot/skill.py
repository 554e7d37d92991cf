"""take_formation_slot: fly to a formation slot (circle or line).

Slots are entities of kind ``"slot"``. A member that owns a slot has its id in
``obs.facts["slot"]`` and is offered that slot only; without an owned slot every visible
slot is offered (the members then share them out through their ``intent`` messages).
"""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, move_and_announce, of_kind, visible

NAME = "take_formation_slot"
ROLES = frozenset({"member"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a formation slot (your own slot)")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    if not allowed(ctx, ROLES):
        return []
    own = obs.facts.get("slot", "")
    slots = of_kind(obs, "slot")
    return [Params(target_id=s.id) for s in slots if not own or s.id == own]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    slot = visible(obs, params.target_id, "slot")
    if slot is None or not allowed(ctx, ROLES):
        return HOLD
    return move_and_announce(NAME, slot.id, slot.pos[0], slot.pos[1], ctx)
