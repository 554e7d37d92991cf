"""Guided navigation (mpe2 ``simple_speaker_listener``): a stationary speaker, the only one
who knows the goal landmark, guides the listeners to it.

Bodies: one speaker (stationary, private fact ``goal_landmark``) and K >= 1 listeners.
mpe2 has exactly one listener; with several, each listener gets its own pair reward and the
speaker the mean (the notes' extension), so K = 1 is mpe2 exactly.

Layout (draws in this order): one group offset (2) for the landmarks (-28, 24), (4, 34),
(32, 20); the goal index (1 draw, uniform over the 3); the spawn jitter (2 each) of the
speaker around (0, -10) and of listener k at spawn row k.

Routing: the speaker reaches every listener regardless of range.
Completion: every listener within 3 m of the goal, 3 rounds. Reward (shared by the pair):
``-‖p_listener - p_goal‖²`` in MPE units², i.e. metres² / 4900.

Reference policy: the speaker signals the goal every round; a listener follows the newest
signal (10 - d/100) and otherwise holds (it has nothing to go on).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, ClassVar, Final

from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest
from aeroweaver_edge.contracts.wire import Entity
from aeroweaver_edge.tasks import policy
from aeroweaver_edge.tasks.base import Layout, Metrics, TaskDefinition
from aeroweaver_edge.tasks.coverage import LANDMARKS_NE, landmark_id
from aeroweaver_edge.tasks.layout import SPAWN_JITTER_M, group_offset, shifted, spawn_base
from aeroweaver_edge.tasks.spec import RoleSpec, TaskSpec
from aeroweaver_edge.world.kinematics import KinematicWorld

if TYPE_CHECKING:
    import numpy as np

    from aeroweaver_edge.tasks.mpe import MpeRewardModel

SPEAKER_AT: Final = (0.0, -10.0)
GOAL_RADIUS_M: Final = 3.0

SPEC = TaskSpec(
    name="guided_navigation",
    title="Guided navigation",
    summary="a stationary speaker guides listeners to a goal landmark",
    description=(
        "One stationary speaker drone knows which landmark is the goal and tells the listener "
        "drones; the listeners cannot tell on their own and must follow the speaker's "
        "directions, instructions or guidance to the right landmark and stop there."
    ),
    keywords=("guide", "speaker", "listener", "instruct", "direct", "tell", "goal", "navigate"),
    mission_text=(
        "The speaker knows which landmark is the goal and guides the listener there; the "
        "listener stops within 3 m of it."
    ),
    roles=(
        RoleSpec(
            "speaker",
            "Tell the listeners which landmark is the goal; stay where you are.",
            min_count=1,
            max_count=1,
            stationary=True,
            facts=("goal_landmark",),
            nouns="speakers?",
        ),
        RoleSpec(
            "listener",
            "Follow the speaker's signal to the goal landmark and stop within 3 m of it.",
            min_count=1,
            nouns="listeners?",
        ),
    ),
    role_counts=lambda n: {"speaker": 1, "listener": n - 1},
    team_size=2,
    mpe_module="simple_speaker_listener",
    routes=(("speaker", "listener"),),
    cues=(
        (r"\blisteners?\b", 2),
        (r"\bspeaker\b", 2),
        (r"\bguid(?:e|es|ing)\b[^.;]{0,40}\bto\b", 2),
        (
            r"\b(?:direct|talk|steer)\w*\b[^.;]{0,40}\b(?:to|onto)\b[^.;]{0,20}"
            r"\b(?:landmark|marker|goal)",
            1,
        ),
        (r"\b(?:knows|tells?|broadcasts?)\b[^.;]{0,30}\b(?:goal|which landmark)", 1),
    ),
)


class GuidedNavigationPolicy:
    def utilities(self, request: DecisionRequest) -> dict[str, float]:
        obs = request.observation

        def rule(c: Candidate) -> float | None:
            if c.skill == "signal_goal":
                return 10.0
            if c.skill == "follow_signal":
                lm = policy.target(obs, c)
                d = policy.distance_to(obs, lm.pos) if lm is not None else 50.0
                return 10.0 - d / 100.0
            if c.skill == "explore_local":
                return -5.0  # a listener without a signal waits for one
            return None

        return policy.score_all(request, rule, wants_something=True)


class GuidedNavigation(TaskDefinition):
    spec: ClassVar[TaskSpec] = SPEC
    reference: ClassVar[GuidedNavigationPolicy] = GuidedNavigationPolicy()

    def setup(self) -> None:
        self.landmark_ids = [landmark_id(k) for k in range(len(LANDMARKS_NE))]
        self.goal = self.landmark_ids[0]
        self._model: MpeRewardModel | None = None

    @property
    def speaker(self) -> str:
        return self.of_role("speaker")[0]

    @property
    def listeners(self) -> list[str]:
        return self.of_role("listener")

    def layout(self, rng: np.random.Generator) -> Layout:
        points = shifted(LANDMARKS_NE, group_offset(rng))
        self.goal = self.landmark_ids[int(rng.integers(len(points)))]
        bases = [SPEAKER_AT, *(spawn_base(k) for k in range(len(self.listeners)))]
        jitter = rng.uniform(-SPAWN_JITTER_M, SPAWN_JITTER_M, (len(bases), 2))
        spawns = [
            (n + float(j[0]), e + float(j[1])) for (n, e), j in zip(bases, jitter, strict=True)
        ]
        down = -self.altitude_m
        entities = [
            Entity(id=lid, kind="landmark", pos=(n, e, down))
            for lid, (n, e) in zip(self.landmark_ids, points, strict=True)
        ]
        return Layout(dict(zip([self.speaker, *self.listeners], spawns, strict=True)), entities)

    def facts(self, world: KinematicWorld, body: str) -> dict[str, str]:
        return {"goal_landmark": self.goal} if body == self.speaker else {}

    def _goal_dist(self, world: KinematicWorld, body: str) -> float:
        g = world.entity(self.goal).pos
        b = world.body(body)
        return math.hypot(b.north - g[0], b.east - g[1])

    def _reward_model(self) -> MpeRewardModel:
        if self._model is None:
            from aeroweaver_edge.tasks.mpe import MpeRewardModel

            self._model = MpeRewardModel("simple_speaker_listener")
        return self._model

    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        model = self._reward_model()
        speaker, listener = model.world.agents
        for ent, lid in zip(model.world.landmarks, self.landmark_ids, strict=True):
            p = world.entity(lid).pos
            model.place(ent, p[0], p[1])
        speaker.goal_a = listener
        speaker.goal_b = model.world.landmarks[self.landmark_ids.index(self.goal)]
        s = world.body(self.speaker)
        model.place(speaker, s.north, s.east)
        out: dict[str, float] = {}
        for lid in self.listeners:
            b = world.body(lid)
            model.place(listener, b.north, b.east)
            out[lid] = model.evaluate()[1]
        out[self.speaker] = math.fsum(out.values()) / len(self.listeners)
        return {b: out[b] for b in self.body_ids}

    def complete(self, world: KinematicWorld, round: int) -> bool:
        return all(self._goal_dist(world, b) <= GOAL_RADIUS_M for b in self.listeners)

    def metrics(self, world: KinematicWorld) -> Metrics:
        out = super().metrics(world)
        dists = {b: self._goal_dist(world, b) for b in self.listeners}
        out["listeners_at_goal"] = float(sum(d <= GOAL_RADIUS_M for d in dists.values()))
        out.update({f"goal_dist_m.{b}": d for b, d in dists.items()})
        return out


TASK = GuidedNavigation
