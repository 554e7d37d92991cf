"""return_in_bounds: head back to the local origin, away from boundary penalties."""

from __future__ import annotations

from aeroweaver_edge.contracts.actions import Intent, MoveTo, Outgoing
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams

NAME = "return_in_bounds"


class Params(SkillParams):
    """No parameters: the destination is always the origin."""


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    return [Params()]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    announce = Outgoing(to="*", kind="intent", body={"skill": NAME, "north": 0.0, "east": 0.0})
    return Intent(MoveTo((0.0, 0.0, -ctx.altitude_m)), messages=(announce,))
