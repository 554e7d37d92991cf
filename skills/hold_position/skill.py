"""hold_position: zero velocity, motion target cleared; always callable."""

from __future__ import annotations

from aeroweaver_edge.contracts.actions import HOLD, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams


class Params(SkillParams):
    """No parameters."""


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    return [Params()]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    return HOLD
