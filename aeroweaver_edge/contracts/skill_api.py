"""What a skill package's ``skill.py`` implements.

A skill package is ``skills/<name>/skill.md`` (front matter + prose for the LLM) and
``skills/<name>/skill.py`` with:

* ``class Params(SkillParams)``: the typed parameters; the JSON Schema shown to LLMs and
  tools is generated from it, never written twice;
* ``def options(obs: Observation, ctx: SkillContext) -> list[Params]``: the callable
  parameterisations right now (e.g. one per visible landmark);
* ``def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent``: what the
  UAV's own body should do. It never touches a vehicle or the network.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pydantic import BaseModel, ConfigDict

from aeroweaver_edge.contracts.defaults import ALTITUDE_M
from aeroweaver_edge.contracts.observation import Observation


class SkillParams(BaseModel):
    """Base of every skill's parameter model: strict, finite, no extra fields."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, str_max_length=64)

    def invocation(self, skill: str) -> str:
        args = ", ".join(f"{k}={v}" for k, v in self.model_dump().items())
        return f"{skill}({args})"


@dataclass(frozen=True)
class SkillContext:
    """Facts an executor may need beyond the observation."""

    uav: str
    uav_index: int
    role: str
    task: str
    altitude_m: float = ALTITUDE_M
    peers: tuple[str, ...] = ()  # ids of the other UAVs in the mission
    settings: dict[str, float] = field(default_factory=dict)


__all__ = ["Observation", "SkillContext", "SkillParams"]
