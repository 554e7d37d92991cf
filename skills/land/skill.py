"""land: descend and land where the UAV is.

A vehicle action: the executor returns Hold plus a ``VehicleAction`` that the daemon's flight
phases carry out through ``Vehicle.land()`` after the approval check (see skill.md).
"""

from __future__ import annotations

from aeroweaver_edge.contracts.actions import Hold, Intent, VehicleAction
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams

NAME = "land"


class Params(SkillParams):
    """No parameters: the UAV lands where it is."""


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    """Offered only in the air."""
    return [Params()] if obs.own.in_air else []


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    return Intent(Hold(), action=VehicleAction("land"))
