"""What the circular and line formations share: owned slots, the Hungarian reward, the policy.

Each member owns one slot (private fact ``slot``; slots are entities of kind ``"slot"``,
markers of kind ``"landmark"``): member k takes slot ``S<k>``, the authors' fixed owned
slots. mpe2 scores the formation with a Hungarian matching of members to ideal positions
(``global_reward``, ρ = 0, so every member gets the same value): ``-mean_i clip(d_i, 0, 2)``
in units. Both formations are normalised to mpe2's native target size (the notes' option A,
the authors' choice): the subclass gives the metric-to-unit scale and what to place.

Completion: every member within 3 m of its own slot, 3 consecutive rounds.
Reference policy: fly to the owned slot (10 - d/100); without one in view, hold.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from typing import TYPE_CHECKING, Any

from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest
from aeroweaver_edge.contracts.wire import Entity
from aeroweaver_edge.tasks import policy
from aeroweaver_edge.tasks.base import NE, Layout, Metrics, TaskDefinition
from aeroweaver_edge.tasks.layout import group_offset, spawn_row
from aeroweaver_edge.world.kinematics import KinematicWorld

if TYPE_CHECKING:
    import numpy as np

    from aeroweaver_edge.tasks.mpe import MpeRewardModel, UnitScale

SLOT_RADIUS_M = 3.0
MEMBER_GOAL = "Take your own slot in the formation and hold within 3 m of it."


def slot_id(k: int) -> str:
    return f"S{k}"


class FormationPolicy:
    def utilities(self, request: DecisionRequest) -> dict[str, float]:
        obs = request.observation
        own = obs.facts.get("slot", "")

        def rule(c: Candidate) -> float | None:
            if c.skill == "take_formation_slot":
                s = policy.target(obs, c)
                d = policy.distance_to(obs, s.pos) if s is not None else 100.0
                return (10.0 if c.params.get("target_id") == own else 2.0) - d / 100.0
            if c.skill == "explore_local":
                return -5.0
            return None

        return policy.score_all(request, rule, wants_something=True)


class Formation(TaskDefinition):
    """Base of ``CircularFormation`` and ``LineFormation``."""

    reference = FormationPolicy()

    def setup(self) -> None:
        self.slots: list[NE] = []
        self.markers: list[NE] = []
        self._model: MpeRewardModel | None = None

    @property
    def members(self) -> list[str]:
        return self.of_role("member")

    @abstractmethod
    def shape(self, offset: NE) -> tuple[list[NE], list[NE]]:
        """(slots, markers) in metres for the group offset: slot k belongs to member k."""

    @abstractmethod
    def scale(self) -> UnitScale:
        """Metres -> units for the current episode (option A normalisation)."""

    @abstractmethod
    def _make_model(self) -> MpeRewardModel: ...

    def _prepare(self, model: MpeRewardModel) -> None:
        """Anything the scenario needs besides positions (the line's expected positions)."""

    def layout(self, rng: np.random.Generator) -> Layout:
        self.slots, self.markers = self.shape(group_offset(rng))
        spawns = spawn_row(rng, range(self.n_uavs))
        down = -self.altitude_m
        entities = [
            Entity(id=slot_id(k), kind="slot", pos=(n, e, down))
            for k, (n, e) in enumerate(self.slots)
        ]
        entities += [
            Entity(id=self.marker_id(k), kind="landmark", pos=(n, e, down))
            for k, (n, e) in enumerate(self.markers)
        ]
        self._model = None
        return Layout(dict(zip(self.members, spawns, strict=True)), entities)

    def marker_id(self, k: int) -> str:
        return f"M{k}"

    def facts(self, world: KinematicWorld, body: str) -> dict[str, str]:
        return {"slot": slot_id(self.index_in_role(body))}

    def _slot_dists(self, world: KinematicWorld) -> dict[str, float]:
        out = {}
        for body in self.members:
            b = world.body(body)
            n, e = self.slots[self.index_in_role(body)]
            out[body] = math.hypot(b.north - n, b.east - e)
        return out

    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        if self._model is None:
            self._model = self._make_model()
        model: Any = self._model
        model.scale = self.scale()
        for ent, body in zip(model.world.agents, self.members, strict=True):
            b = world.body(body)
            model.place(ent, b.north, b.east)
        for ent, (n, e) in zip(model.world.landmarks, self.markers, strict=True):
            model.place(ent, n, e)
        self._prepare(model)
        values: list[float] = model.evaluate()
        return dict(zip(self.members, values, strict=True))

    def complete(self, world: KinematicWorld, round: int) -> bool:
        return all(d <= SLOT_RADIUS_M for d in self._slot_dists(world).values())

    def metrics(self, world: KinematicWorld) -> Metrics:
        out = super().metrics(world)
        d = self._slot_dists(world)
        out["members_in_slot"] = float(sum(x <= SLOT_RADIUS_M for x in d.values()))
        out["slot_dist_mean_m"] = math.fsum(d.values()) / len(d)
        out["slot_dist_max_m"] = max(d.values())
        return out


__all__ = ["MEMBER_GOAL", "SLOT_RADIUS_M", "Formation", "FormationPolicy", "slot_id"]
