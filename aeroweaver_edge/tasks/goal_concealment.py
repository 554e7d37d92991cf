"""Goal concealment (mpe2 ``simple_adversary``): informed UAVs reach the goal landmark
without giving away which landmark it is to an adversary the world flies.

Bodies: N informed UAVs (private fact ``goal_landmark``) and the scripted ``adversary0``,
which does not know the goal. Landmarks: the authors' three at (-28, 24), (4, 34),
(32, 20) (mpe2 would use N; only the goal enters the reward, so the extra one is harmless),
and for N > 3 N landmarks, the rest scattered.

Layout (draws in this order): one group offset (2) for the authors' landmarks; the goal
index (1 draw, uniform over the landmarks); spawn jitter (2 each) of the informed UAVs at
spawn rows 0..N-1 and of the adversary at row N; the extra landmarks for N > 3.

Adversary policy (world-run, deterministic): ``infer_goal`` on the landmark closest to any
informed UAV it sees (45 m; ties by ids), otherwise ``explore_local`` (index 0).

Rewards: ``simple_adversary`` at 70 m per unit. Informed (shared):
``-min_informed d(i, goal) + Σ_adversaries d(a, goal)``; adversary ``-d(a, goal)``.
Horizon only. Metrics: the nearest informed UAV's and the adversary's distance to the goal.

Reference policy: the informed UAV nearest the goal among those this one knows of (itself,
visible informed peers, senders of intent messages; ties by id) approaches the goal; the
others approach the nearest decoy not already claimed (greedy), else explore.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, ClassVar

from aeroweaver_edge.contracts.observation import horizontal_distance
from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest
from aeroweaver_edge.contracts.wire import Entity, InboxMessage
from aeroweaver_edge.tasks import policy, scripted
from aeroweaver_edge.tasks.base import Action, Layout, Metrics, TaskDefinition
from aeroweaver_edge.tasks.coverage import LANDMARKS_NE, landmark_id
from aeroweaver_edge.tasks.layout import group_offset, scatter, shifted, spawn_row
from aeroweaver_edge.tasks.spec import RED, RoleSpec, TaskSpec
from aeroweaver_edge.world.kinematics import KinematicWorld

if TYPE_CHECKING:
    import numpy as np

    from aeroweaver_edge.tasks.mpe import MpeRewardModel

SPEC = TaskSpec(
    name="goal_concealment",
    title="Goal concealment",
    summary="informed UAVs reach the goal landmark without revealing it to an adversary",
    description=(
        "Informed drones know which landmark is the real goal and keep one of them on it, "
        "while the others visit decoy landmarks to mislead a watching adversary that tries "
        "to work out the true goal. Hide the objective, deceive, feint."
    ),
    keywords=("conceal", "decoy", "hide", "deceive", "mislead", "adversary", "goal", "feint"),
    mission_text=(
        "Keep a drone on the goal landmark while the others visit decoy landmarks, so the "
        "adversary cannot tell which landmark is the goal."
    ),
    roles=(
        RoleSpec(
            "informed",
            "Keep a drone on the goal landmark while others visit decoy landmarks so the "
            "adversary cannot tell which is the goal.",
            min_count=1,
            facts=("goal_landmark",),
            nouns="informed (?:drones?|uavs?|agents?)",
        ),
    ),
    role_counts=lambda n: {"informed": n},
    team_size=2,
    mpe_module="simple_adversary",
    scripted=(
        RoleSpec(
            "adversary",
            "Find the goal landmark.",
            min_count=1,
            max_count=1,
            scripted=True,
            team=RED,
            nouns="adversar(?:y|ies)",
        ),
    ),
    scripted_counts=lambda n: {"adversary": 1},
    cues=(
        (r"\bconceal\w*\b|\bdecoys?\b", 2),
        (r"\bhid(?:e|es|ing)\b[^.;]{0,30}\b(?:goal|objective|target)\b", 2),
        (r"\bwithout (?:revealing|giving away|showing)\b|\bmislead\w*\b", 2),
        (r"\b(?:goal|target|objective)\b[^.;]{0,20}\bsecret\b|\bfake\b|\bfalse target\b", 1),
        (r"\badversary\b|\bobserver\b|\bwatching\b", 1),
    ),
)


class ConcealmentPolicy:
    def utilities(self, request: DecisionRequest) -> dict[str, float]:
        obs = request.observation
        goal = obs.facts.get("goal_landmark", "")
        landmarks = {e.id: e.pos for e in obs.of_kind("landmark")}
        team = policy.known_positions(obs, roles={"informed"})
        keeper = obs.uav
        if goal in landmarks:
            g = landmarks[goal]
            keeper = min(team, key=lambda u: (horizontal_distance(team[u], g), u))
        decoys = {k: p for k, p in landmarks.items() if k != goal}
        others = {u: p for u, p in team.items() if u != keeper}
        owner = policy.greedy_assignment(others, decoys)

        def rule(c: Candidate) -> float | None:
            t = policy.target(obs, c)
            d = 1.0 if t is None else policy.distance_to(obs, t.pos) / 100.0
            if c.skill == "approach_goal":
                return (10.0 if keeper == obs.uav else 0.0) - d
            if c.skill == "approach_decoy":
                holder = owner.get(t.id) if t is not None else None
                mine = keeper != obs.uav and holder == obs.uav
                return (8.0 if mine else 4.0 if holder is None else -1.0) - d
            return None

        return policy.score_all(request, rule, wants_something=bool(landmarks))


class GoalConcealment(TaskDefinition):
    spec: ClassVar[TaskSpec] = SPEC
    reference: ClassVar[ConcealmentPolicy] = ConcealmentPolicy()

    def setup(self) -> None:
        n_landmarks = max(len(LANDMARKS_NE), self.n_uavs)
        self.landmark_ids = [landmark_id(k) for k in range(n_landmarks)]
        self.goal = self.landmark_ids[0]
        self._model: MpeRewardModel | None = None

    @property
    def informed(self) -> list[str]:
        return self.of_role("informed")

    @property
    def adversaries(self) -> list[str]:
        return self.of_role("adversary")

    def layout(self, rng: np.random.Generator) -> Layout:
        authors = shifted(LANDMARKS_NE, group_offset(rng))
        self.goal = self.landmark_ids[int(rng.integers(len(self.landmark_ids)))]
        order = [*self.informed, *self.adversaries]
        spawns = spawn_row(rng, range(len(order)))
        points = authors + scatter(rng, len(self.landmark_ids) - len(authors), authors)
        down = -self.altitude_m
        entities = [
            Entity(id=lid, kind="landmark", pos=(n, e, down))
            for lid, (n, e) in zip(self.landmark_ids, points, strict=True)
        ]
        return Layout(dict(zip(order, spawns, strict=True)), entities)

    def facts(self, world: KinematicWorld, body: str) -> dict[str, str]:
        return {"goal_landmark": self.goal}

    def scripted_actions(
        self,
        world: KinematicWorld,
        round: int,
        inboxes: Mapping[str, Sequence[InboxMessage]],
    ) -> dict[str, Action]:
        out: dict[str, Action] = {}
        for adv in self.adversaries:
            me = world.body(adv)
            ctx = scripted.context(me, self.index_in_role(adv), self.name, self.altitude_m)
            seen = self.visible(world, adv)
            agents = [e for e in seen if e.kind == "uav" and e.role == "informed"]
            landmarks = [e for e in world.entities() if e.kind == "landmark"]
            pairs = sorted(
                (horizontal_distance(a.pos, lm.pos), lm.id, a.id, lm)
                for a in agents
                for lm in landmarks
            )
            if pairs:
                lm = pairs[0][3]
                out[adv] = scripted.fly_to(world, me, (lm.pos[0], lm.pos[1]))
            else:
                out[adv] = scripted.fly_to(world, me, scripted.explore_point(round, ctx))
        return out

    def _goal_dist(self, world: KinematicWorld, body: str) -> float:
        g = world.entity(self.goal).pos
        b = world.body(body)
        return math.hypot(b.north - g[0], b.east - g[1])

    def _reward_model(self) -> MpeRewardModel:
        if self._model is None:
            from aeroweaver_edge.tasks.mpe import MpeRewardModel

            self._model = MpeRewardModel("simple_adversary", make_world_args=(len(self.informed),))
        return self._model

    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        model = self._reward_model()
        mw = model.world
        goal = mw.landmarks[0]  # only the goal enters the reward: it stands for ours
        g = world.entity(self.goal).pos
        model.place(goal, g[0], g[1])
        order = [*self.adversaries, *self.informed]  # mpe2: the adversary first
        for ent, body in zip(mw.agents, order, strict=True):
            b = world.body(body)
            model.place(ent, b.north, b.east)
            ent.goal_a = goal
        return dict(zip(order, model.evaluate(), strict=True))

    def complete(self, world: KinematicWorld, round: int) -> bool:
        return False  # horizon only

    def metrics(self, world: KinematicWorld) -> Metrics:
        out = super().metrics(world)
        out["informed_goal_dist_m"] = min(self._goal_dist(world, b) for b in self.informed)
        for adv in self.adversaries:
            out[f"adversary_goal_dist_m.{adv}"] = self._goal_dist(world, adv)
        return out


TASK = GoalConcealment
