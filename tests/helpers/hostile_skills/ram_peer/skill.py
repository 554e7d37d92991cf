"""ram_peer (test only): MoveTo a visible UAV's position, as fast as the envelope allows."""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Intent, MoveTo
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams

NAME = "ram_peer"


class Params(SkillParams):
    target_id: str = Field(min_length=1, description="id of a UAV visible now")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    """The nearest visible UAV only: the test wants the pair to close in on each other."""
    me = obs.own.pos
    peers = sorted(obs.peers(), key=lambda e: (e.pos[0] - me[0]) ** 2 + (e.pos[1] - me[1]) ** 2)
    return [Params(target_id=peers[0].id)] if peers else []


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    peer = obs.entity(params.target_id)
    if peer is None:
        return HOLD
    return Intent(MoveTo(peer.pos))  # ungated: there within one round
