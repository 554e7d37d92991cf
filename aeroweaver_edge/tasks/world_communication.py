"""World communication (mpe2 ``simple_world_comm``): a long-sighted leader spots foragers and
signals them to its pursuers, who catch them; the foragers hide in forests.

Bodies: one leader (sensing 100 m), N - 1 pursuers (45 m) and two scripted foragers
(``forager0``/``forager1``, 15 m/s against 11 m/s, as mpe2's 1.3 : 1.0). Two food sources
at (25, 25) and (-20, 28) and two forests (radius 10 m) at food - (10, 8); no obstacles.

Layout (draws in this order): one group offset (2) for food and forests together; spawn
jitter (2 each) of the controlled UAVs at spawn rows 0..N-1, then of the foragers at the
next two rows.

Forest occlusion (mpe2's observation rule, with the authors' 10 m forests): a body sees
another UAV only if both are in the same forest or neither is in any forest; the leader
sees everything. Static objects are not occluded.

Forager policy (world-run, deterministic, the notes' rule): ``evade_peer`` from the nearest
leader or pursuer within 18 m; else ``seek_cover`` (nearest forest) when ``round % 30 > 20``
(rounds 21-23 of 24), else ``seek_food`` (nearest food). Foragers know where food and
forests are (they are the environment).

Rewards: ``simple_world_comm`` at 70 m per unit. Leader and pursuers:
``-0.1 min_forager d + 5 x (colliding forager-adversary pairs over all adversaries)``
(contact below 0.12 u = 8.4 m). Foragers: ``-5 x colliding adversaries - 2 Σ_axes b(|x|)
+ 2 x food touched (below 5.25 m) - 0.05 min_food d``. Horizon only (no early end).
Metrics: food visits (forager-food pairs within 3 m, summed over rounds), foragers in cover,
contacts (adversary-forager pairs within 3 m).

Reference policy: leader and pursuers pursue the nearest visible forager (10 - d/100); a
pursuer without one follows the leader's target report (5 - d/100), else explores.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, ClassVar, Final

from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest
from aeroweaver_edge.contracts.wire import Entity, InboxMessage
from aeroweaver_edge.tasks import policy, scripted
from aeroweaver_edge.tasks.base import NE, Action, Layout, Metrics, TaskDefinition
from aeroweaver_edge.tasks.layout import group_offset, shifted, spawn_row
from aeroweaver_edge.tasks.pursuit_evasion import _reported_distance
from aeroweaver_edge.tasks.spec import RED, RoleSpec, TaskSpec
from aeroweaver_edge.world.kinematics import Body, KinematicWorld

if TYPE_CHECKING:
    import numpy as np

    from aeroweaver_edge.tasks.mpe import MpeRewardModel

FOOD_NE: Final = ((25.0, 25.0), (-20.0, 28.0))
FOREST_SHIFT: Final = (-10.0, -8.0)
FOREST_RADIUS_M: Final = 10.0
VISIT_M: Final = 3.0
CONTACT_M: Final = 3.0
FORAGER_THREAT_M: Final = 18.0
FORAGER_SPEED_MPS: Final = 15.0
LEADER_SENSING_M: Final = 100.0

SPEC = TaskSpec(
    name="world_communication",
    title="World communication",
    summary="a leader signals foragers' positions to pursuers who catch them",
    description=(
        "A leader drone with a long-range view spots foragers that gather food and hide in "
        "forests, and signals their positions to the pursuer drones, who hunt and catch them "
        "even when they are out of sight."
    ),
    keywords=("leader", "forager", "forest", "food", "hunt", "signal", "spot", "hide"),
    mission_text=(
        "The leader spots the foragers and signals their positions; the pursuers catch them, "
        "even when they hide in the forests."
    ),
    roles=(
        RoleSpec(
            "leader",
            "Spot foragers with your long-range sensor, signal their positions to the pursuers "
            "and chase the nearest one.",
            min_count=1,
            max_count=1,
            sensing_radius_m=LEADER_SENSING_M,
            nouns="leaders?",
        ),
        RoleSpec(
            "pursuer",
            "Catch foragers, following the leader's target messages when they are out of sight "
            "or hidden in a forest.",
            min_count=0,
            nouns="pursuers?|chasers?|hunters?|interceptors?",
        ),
    ),
    role_counts=lambda n: {"leader": 1, "pursuer": n - 1},
    team_size=3,
    mpe_module="simple_world_comm",
    scripted=(
        RoleSpec(
            "forager",
            "Gather food and escape the pursuers.",
            min_count=2,
            max_count=2,
            scripted=True,
            team=RED,
            nouns="foragers?",
            max_speed_mps=FORAGER_SPEED_MPS,
        ),
    ),
    scripted_counts=lambda n: {"forager": 2},
    cues=(
        (r"\bforagers?\b", 2),
        (r"\bforests?\b|\bfood\b", 2),
        (r"\bleader\b|\blead (?:drone|uav|aircraft)\b", 1),
        (r"\bhunt\w*\b|\bcatch\b|\bgather\w*\b", 1),
    ),
)


class WorldCommunicationPolicy:
    def utilities(self, request: DecisionRequest) -> dict[str, float]:
        obs = request.observation
        foragers = [e for e in obs.peers() if e.role == "forager"]

        def rule(c: Candidate) -> float | None:
            if c.skill == "pursue_target":
                t = policy.target(obs, c)
                return -5.0 if t is None else 10.0 - policy.distance_to(obs, t.pos) / 100.0
            if c.skill == "signal_target":
                t = policy.target(obs, c)
                return -5.0 if t is None else 6.0 - policy.distance_to(obs, t.pos) / 100.0
            if c.skill == "follow_peer":
                return 5.0 - _reported_distance(request, c) / 100.0
            return None

        wants = bool(foragers) or any(c.skill == "follow_peer" for c in request.candidates)
        return policy.score_all(request, rule, wants_something=wants)


class WorldCommunication(TaskDefinition):
    spec: ClassVar[TaskSpec] = SPEC
    reference: ClassVar[WorldCommunicationPolicy] = WorldCommunicationPolicy()

    def setup(self) -> None:
        self.food_ids = [f"F{k}" for k in range(len(FOOD_NE))]
        self.forest_ids = [f"W{k}" for k in range(len(FOOD_NE))]
        self.food_visits = 0
        self._model: MpeRewardModel | None = None

    @property
    def adversaries(self) -> list[str]:
        """Leader first, then the pursuers (mpe2's adversary order)."""
        return [*self.of_role("leader"), *self.of_role("pursuer")]

    @property
    def foragers(self) -> list[str]:
        return self.of_role("forager")

    def layout(self, rng: np.random.Generator) -> Layout:
        self.food_visits = 0
        food = shifted(FOOD_NE, group_offset(rng))
        forests = shifted(food, FOREST_SHIFT)
        order = [*self.uav_ids, *self.foragers]
        spawns = spawn_row(rng, range(len(order)))
        down = -self.altitude_m
        entities = [
            Entity(id=fid, kind="food", pos=(n, e, down))
            for fid, (n, e) in zip(self.food_ids, food, strict=True)
        ]
        entities += [
            Entity(id=wid, kind="forest", pos=(n, e, down))
            for wid, (n, e) in zip(self.forest_ids, forests, strict=True)
        ]
        return Layout(dict(zip(order, spawns, strict=True)), entities)

    # -- perception: forest occlusion -------------------------------------------------------

    def forest_of(self, world: KinematicWorld, body: Body) -> str | None:
        for wid in self.forest_ids:
            p = world.entity(wid).pos
            if math.hypot(body.north - p[0], body.east - p[1]) <= FOREST_RADIUS_M:
                return wid
        return None

    def sensed(self, world: KinematicWorld, body: str) -> list[Entity]:
        seen = super().sensed(world, body)
        if self.role_of(body) == "leader":
            return seen
        mine = self.forest_of(world, world.body(body))
        return [
            e for e in seen if e.kind != "uav" or self.forest_of(world, world.body(e.id)) == mine
        ]

    # -- foragers -------------------------------------------------------------------------

    def scripted_actions(
        self,
        world: KinematicWorld,
        round: int,
        inboxes: Mapping[str, Sequence[InboxMessage]],
    ) -> dict[str, Action]:
        return {f: self._forage(world, f, round) for f in self.foragers}

    def _nearest(self, body: Body, points: Sequence[NE]) -> NE:
        return min(points, key=lambda p: (math.hypot(body.north - p[0], body.east - p[1]), p))

    def _forage(self, world: KinematicWorld, forager: str, round: int) -> Action:
        me = world.body(forager)
        ctx = scripted.context(me, self.index_in_role(forager), self.name, self.altitude_m)
        threats = sorted(
            (math.hypot(b.north - me.north, b.east - me.east), b.id, b)
            for b in (world.body(a) for a in self.adversaries)
        )
        if threats and threats[0][0] <= FORAGER_THREAT_M:
            return scripted.fly_to(world, me, scripted.escape_from(me, threats[0][2], ctx))
        ids = self.forest_ids if round % 30 > 20 else self.food_ids
        points = [(world.entity(i).pos[0], world.entity(i).pos[1]) for i in ids]
        return scripted.fly_to(world, me, self._nearest(me, points))

    # -- scoring ----------------------------------------------------------------------------

    def after_step(self, world: KinematicWorld) -> None:
        for f in self.foragers:
            b = world.body(f)
            for fid in self.food_ids:
                p = world.entity(fid).pos
                self.food_visits += math.hypot(b.north - p[0], b.east - p[1]) <= VISIT_M

    def _reward_model(self) -> MpeRewardModel:
        if self._model is None:
            from aeroweaver_edge.tasks.mpe import MpeRewardModel

            self._model = MpeRewardModel(
                "simple_world_comm",
                make_world_args=(
                    len(self.foragers),
                    len(self.adversaries),
                    0,
                    len(self.food_ids),
                    len(self.forest_ids),
                ),
            )
        return self._model

    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        model = self._reward_model()
        order = [*self.adversaries, *self.foragers]
        for ent, body in zip(model.world.agents, order, strict=True):
            b = world.body(body)
            model.place(ent, b.north, b.east)
        for ent, eid in zip(model.world.landmarks, [*self.food_ids, *self.forest_ids], strict=True):
            p = world.entity(eid).pos
            model.place(ent, p[0], p[1])
        return dict(zip(order, model.evaluate(), strict=True))

    def complete(self, world: KinematicWorld, round: int) -> bool:
        return False  # horizon only

    def metrics(self, world: KinematicWorld) -> Metrics:
        out = super().metrics(world)
        out["food_visits"] = float(self.food_visits)
        out["foragers_in_cover"] = float(
            sum(self.forest_of(world, world.body(f)) is not None for f in self.foragers)
        )
        contacts = 0
        for f in self.foragers:
            fb = world.body(f)
            for a in self.adversaries:
                ab = world.body(a)
                contacts += math.hypot(fb.north - ab.north, fb.east - ab.east) <= CONTACT_M
        out["contacts"] = float(contacts)
        return out


TASK = WorldCommunication
