"""meet_collector: a deposit UAV flies toward a collector that carries its colour.

A deposit's colour comes from its role (``deposit_red`` -> ``red``). Whether a collector
is loaded is known from the newest message that collector sent with a ``cargo`` field (the
collector skills put it in their ``intent`` messages); entities carry no cargo field.
"""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import move_and_announce, nearest_first_k, of_kind, visible

NAME = "meet_collector"
PREFIX = "deposit_"


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a visible loaded collector")


def _colour(ctx: SkillContext) -> str | None:
    colour = ctx.role.removeprefix(PREFIX)
    return colour if ctx.role.startswith(PREFIX) and colour else None


def announced_cargo(obs: Observation) -> dict[str, str]:
    """Sender -> cargo colour ('' when empty) from each sender's newest cargo report."""
    out: dict[str, str] = {}
    for m in sorted(obs.messages, key=lambda m: (m.round, m.h.seq)):
        cargo = m.body.get("cargo")
        if isinstance(cargo, str):
            out[m.h.sender] = cargo
    return out


def _loaded(obs: Observation, colour: str) -> set[str]:
    return {uav for uav, cargo in announced_cargo(obs).items() if cargo == colour}


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    colour = _colour(ctx)
    if colour is None:
        return []
    loaded = _loaded(obs, colour)
    carriers = [e for e in of_kind(obs, "uav", {"collector"}) if e.id in loaded]
    return [Params(target_id=e.id) for e in nearest_first_k(obs, carriers, ctx)]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    colour = _colour(ctx)
    collector = visible(obs, params.target_id, "uav", {"collector"})
    if colour is None or collector is None or collector.id not in _loaded(obs, colour):
        return HOLD
    north, east = collector.pos[0], collector.pos[1]
    return move_and_announce(NAME, collector.id, north, east, ctx)
