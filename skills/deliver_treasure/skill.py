"""deliver_treasure: a loaded collector flies to the deposit that accepts its cargo.

Deposits are UAVs (kind ``"uav"``) with role ``deposit_<colour>``; the collector's load is
``obs.facts["cargo"]`` (a colour, set by the simulator). The simulator performs the delivery.
"""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, move_and_announce, of_kind, visible

NAME = "deliver_treasure"
ROLES = frozenset({"collector"})


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a visible deposit matching the cargo")


def _deposit_role(obs: Observation) -> str | None:
    cargo = obs.facts.get("cargo", "")
    return f"deposit_{cargo}" if cargo else None


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    role = _deposit_role(obs)
    if role is None or not allowed(ctx, ROLES):
        return []
    return [Params(target_id=e.id) for e in of_kind(obs, "uav", {role})]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    role = _deposit_role(obs)
    deposit = None if role is None else visible(obs, params.target_id, "uav", {role})
    if deposit is None or not allowed(ctx, ROLES):
        return HOLD
    cargo = obs.facts["cargo"]
    return move_and_announce(NAME, deposit.id, deposit.pos[0], deposit.pos[1], ctx, cargo=cargo)
