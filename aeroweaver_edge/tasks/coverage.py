"""Coverage (mpe2 ``simple_spread``): N searchers spread out to cover N landmarks.

Layout (north/east metres, draws in this order): one group offset (2 draws) for the
authors' landmarks (-28, 24), (4, 34), (32, 20); the spawn jitter of every UAV (2 each);
then, for N > 3, N - 3 extra landmarks scattered in the arena (``layout.scatter``). With
N = 1 or 2 the first N of the authors' landmarks are used, so there are always N
landmarks, as in mpe2's ``simple_spread_v3(N)``; N = 3 is the authors' layout exactly.

Completion: every landmark has a UAV within 3 m, 3 consecutive rounds; horizon 24.
Rewards: ``simple_spread`` at 70 m per unit with ρ = 0.5:
``r_i = 0.5 * (-Σ_landmarks min_agents d) + 0.5 * (-#{j != i: d(i, j) < 0.30 u = 21 m})``.
No private facts; every searcher senses 45 m.

Reference policy: the greedy nearest-uncovered assignment over the UAVs this one knows of
(visible peers and the senders of ``intent`` messages, at the positions they reported):
its own landmark scores 10 - d/100, an unclaimed one 5 - d/100, a claimed one -d/100.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, ClassVar, Final

from aeroweaver_edge.contracts.observation import horizontal_distance
from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest
from aeroweaver_edge.contracts.wire import Entity
from aeroweaver_edge.tasks import policy
from aeroweaver_edge.tasks.base import NE, Layout, Metrics, TaskDefinition
from aeroweaver_edge.tasks.layout import group_offset, scatter, shifted, spawn_row
from aeroweaver_edge.tasks.spec import RoleSpec, TaskSpec
from aeroweaver_edge.world.kinematics import KinematicWorld

if TYPE_CHECKING:
    import numpy as np

    from aeroweaver_edge.tasks.mpe import MpeRewardModel, UnitScale

LANDMARKS_NE: Final = ((-28.0, 24.0), (4.0, 34.0), (32.0, 20.0))
COVER_RADIUS_M: Final = 3.0

SPEC = TaskSpec(
    name="coverage",
    title="Coverage",
    summary="cover every landmark with one UAV each",
    description=(
        "Searchers spread out over the area so that every landmark has a drone on top of it, "
        "one drone per landmark, without crowding or colliding. Occupy, survey and hold "
        "distinct points of interest, sites or markers."
    ),
    keywords=("coverage", "cover", "landmark", "spread", "occupy", "survey", "distribute"),
    mission_text="Cover every landmark with one drone each and hold there; avoid collisions.",
    roles=(
        RoleSpec(
            "searcher",
            "Reach a landmark no other drone is covering and stay within 3 m of it.",
            min_count=1,
            nouns="searchers?",
        ),
    ),
    role_counts=lambda n: {"searcher": n},
    team_size=3,
    mpe_module="simple_spread",
    cues=(
        (r"\bcover(?:s|ed|ing)?\b[^.;]{0,30}\blandmarks\b", 2),
        (r"\bcoverage\b", 2),
        (r"\bspread\b[^.;]{0,30}\b(?:out|over|across)\b", 2),
        (r"\b(?:every|each|all(?: \w+)?) (?:of the )?landmarks?\b", 1),
        (r"\bone (?:drone|uav|aircraft) (?:per|on|over|to|at) (?:each|every)\b", 1),
        (r"\bcover(?:s|ed|ing)?\b", 1),
    ),
)


def landmark_id(index: int) -> str:
    return f"L{index}"


class SpreadRewards:
    """``simple_spread`` rewards: ``(1 - ρ) * global + ρ * collisions_i`` (ρ = 0.5).

    ``global = -Σ_landmarks min_agents d`` and the local term is ``-1`` per other agent
    closer than 0.30 units (21 m). Built with mpe2 1.1.1's defaults (``curriculum=False``:
    the collision penalty is always on), matching ``simple_spread_v3``.

    ``n_landmarks`` may differ from ``n_agents`` (mpe2 ties them): the world is made with
    ``max(n_agents, n_landmarks)`` entities of each kind and the surplus dropped before reset,
    which leaves every remaining entity exactly as mpe2 configures it.
    """

    def __init__(
        self,
        n_agents: int,
        n_landmarks: int = 3,
        *,
        local_ratio: float = 0.5,
        scale: UnitScale | None = None,
    ) -> None:
        from aeroweaver_edge.tasks.mpe import MpeRewardModel

        if n_agents < 1 or n_landmarks < 1:
            raise ValueError("simple_spread needs at least one agent and one landmark")
        model = MpeRewardModel(
            "simple_spread",
            make_world_args=(max(n_agents, n_landmarks),),
            local_ratio=local_ratio,
            scale=scale,
        )
        world = model.world
        world.agents = world.agents[:n_agents]
        world.landmarks = world.landmarks[:n_landmarks]
        model.reset()
        self.model: MpeRewardModel = model
        self.n_agents = n_agents
        self.n_landmarks = n_landmarks

    def __call__(self, agents: Sequence[NE], landmarks: Sequence[NE]) -> list[float]:
        """Rewards for agents at ``agents`` (north, east metres) given ``landmarks``."""
        if len(agents) != self.n_agents or len(landmarks) != self.n_landmarks:
            raise ValueError(
                f"expected {self.n_agents} agents and {self.n_landmarks} landmarks, "
                f"got {len(agents)} and {len(landmarks)}"
            )
        model = self.model
        for ent, (n, e) in zip(model.world.agents, agents, strict=True):
            model.place(ent, n, e)
        for ent, (n, e) in zip(model.world.landmarks, landmarks, strict=True):
            model.place(ent, n, e)
        return model.evaluate()


class CoveragePolicy:
    """The greedy nearest-uncovered assignment (see the module docstring)."""

    def utilities(self, request: DecisionRequest) -> dict[str, float]:
        obs = request.observation
        landmarks = {e.id: e.pos for e in obs.of_kind("landmark")}
        owner = policy.greedy_assignment(policy.known_positions(obs), landmarks)

        def rule(c: Candidate) -> float | None:
            if c.skill != "cover_landmark":
                return None
            lm = policy.target(obs, c)
            if lm is None or lm.kind != "landmark":
                return -5.0
            d = horizontal_distance(obs.own.pos, lm.pos) / 100.0
            holder = owner.get(lm.id)
            if holder == obs.uav:
                return 10.0 - d
            return (5.0 if holder is None else 0.0) - d

        return policy.score_all(request, rule, wants_something=bool(landmarks))


class Coverage(TaskDefinition):
    spec: ClassVar[TaskSpec] = SPEC
    reference: ClassVar[CoveragePolicy] = CoveragePolicy()

    def setup(self) -> None:
        self.landmark_ids = [landmark_id(k) for k in range(self.n_uavs)]
        self._rewards: SpreadRewards | None = None  # built on first use

    def layout(self, rng: np.random.Generator) -> Layout:
        n = self.n_uavs
        authors = shifted(LANDMARKS_NE, group_offset(rng))
        spawns = spawn_row(rng, range(n))
        points = authors[:n] + scatter(rng, max(0, n - len(authors)), authors)
        down = -self.altitude_m
        entities = [
            Entity(id=landmark_id(k), kind="landmark", pos=(p[0], p[1], down))
            for k, p in enumerate(points)
        ]
        return Layout(dict(zip(self.uav_ids, spawns, strict=True)), entities)

    def _landmark_ne(self, world: KinematicWorld) -> list[NE]:
        return [(p[0], p[1]) for p in (world.entity(k).pos for k in self.landmark_ids)]

    def _nearest_m(self, world: KinematicWorld) -> dict[str, float]:
        bodies = [world.body(u) for u in self.uav_ids]
        return {
            lid: min(math.hypot(b.north - n, b.east - e) for b in bodies)
            for lid, (n, e) in zip(self.landmark_ids, self._landmark_ne(world), strict=True)
        }

    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        if self._rewards is None:
            self._rewards = SpreadRewards(self.n_uavs, len(self.landmark_ids), local_ratio=0.5)
        ids = self.uav_ids
        agents = [(b.north, b.east) for b in (world.body(u) for u in ids)]
        values = self._rewards(agents, self._landmark_ne(world))
        return dict(zip(ids, values, strict=True))

    def complete(self, world: KinematicWorld, round: int) -> bool:
        return all(d <= COVER_RADIUS_M for d in self._nearest_m(world).values())

    def metrics(self, world: KinematicWorld) -> Metrics:
        nearest = self._nearest_m(world)
        out = super().metrics(world)
        out["covered_landmarks"] = float(sum(d <= COVER_RADIUS_M for d in nearest.values()))
        out.update({f"landmark_min_dist_m.{k}": d for k, d in nearest.items()})
        return out


TASK = Coverage
