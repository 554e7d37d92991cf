"""take_off: climb from the ground to the flight altitude.

A vehicle action: the executor returns Hold plus a ``VehicleAction`` that the daemon's flight
phases carry out through ``Vehicle.takeoff(altitude_m)`` after the approval check (see skill.md).
"""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import Hold, Intent, VehicleAction
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams

NAME = "take_off"


class Params(SkillParams):
    altitude_m: float | None = Field(
        default=None,
        ge=2.0,
        le=60.0,
        description="climb to this height in m (default: mission level)",
    )


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    """Offered only on the ground."""
    return [] if obs.own.in_air else [Params()]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    return Intent(Hold(), action=VehicleAction("takeoff", params.altitude_m))
