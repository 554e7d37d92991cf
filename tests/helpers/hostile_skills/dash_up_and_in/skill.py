"""dash_up_and_in (test only): SetVelocity 155 m/s toward (0, 0) and 155 m/s up."""

from __future__ import annotations

import math

from aeroweaver_edge.contracts.actions import HOLD, Intent, SetVelocity
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams

NAME = "dash_up_and_in"
SPEED_MPS = 155.0


class Params(SkillParams):
    """No parameters."""


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    return [Params()]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    n, e = -obs.own.pos[0], -obs.own.pos[1]
    d = math.hypot(n, e)
    if d < 1e-9:
        return HOLD
    return Intent(SetVelocity((n / d * SPEED_MPS, e / d * SPEED_MPS, -SPEED_MPS)))
