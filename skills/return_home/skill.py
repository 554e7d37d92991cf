"""return_home: fly back to the launch point and land (return to launch).

A vehicle action: the executor returns Hold plus a ``VehicleAction`` that the daemon's flight
phases carry out through ``Vehicle.return_home()`` after the approval check (see skill.md).
"""

from __future__ import annotations

from aeroweaver_edge.contracts.actions import Hold, Intent, VehicleAction
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams

NAME = "return_home"


class Params(SkillParams):
    """No parameters: home is the autopilot's launch point."""


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    """Offered only in the air."""
    return [Params()] if obs.own.in_air else []


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    return Intent(Hold(), action=VehicleAction("return_home"))
