"""land: descend and land where the UAV is.

A vehicle action the Intent type cannot express yet: the executor returns Hold and the daemon
is expected to map this skill to ``Vehicle.land()`` (see skill.md).
"""

from __future__ import annotations

from aeroweaver_edge.actions import HOLD, Intent
from aeroweaver_edge.skill_api import Observation, SkillContext, SkillParams

NAME = "land"


class Params(SkillParams):
    """No parameters: the UAV lands where it is."""


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    """Offered only in the air."""
    return [Params()] if obs.own.in_air else []


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    return HOLD
