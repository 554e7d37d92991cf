"""leave_fence (test only): MoveTo a point 1 km west of the default fence (east -1070 m)."""

from __future__ import annotations

from aeroweaver_edge.contracts.actions import Intent, MoveTo
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams

NAME = "leave_fence"
TARGET_EAST_M = -1070.0


class Params(SkillParams):
    """No parameters."""


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    return [Params()]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    return Intent(MoveTo((obs.own.pos[0], TARGET_EAST_M, -ctx.altitude_m)))
