"""Pursuit-evasion (mpe2 ``simple_tag``): pursuers catch a faster evader the world flies.

Bodies: N pursuers (ours) and one scripted evader (``evader0``, 15 m/s against the pursuers'
11 m/s, as in the authors' mock). No obstacles (the authors' mock has none).

Layout (draws in this order): pursuer spawn jitter (2 each, spawn row 0..N-1), then the
evader's jitter (2) around (0, 5).

Evader policy (world-run, deterministic): beyond 63 m from the centre it heads for the
origin (``return_in_bounds``). Otherwise, with a pursuer within 35 m, it runs from the
nearest one: ``evade_peer``'s escape point E (the threat mirrored through the evader, at
least 20 m away, inside ±60 m) gives the bearing; the bearing persists, the previous round's
bearing is averaged in while it still points away from the nearest threat (persistent escape
bearing); every other pursuer within 35 m pushes the target 8 m further away from it (8 m
repulsion); the target is clamped to ±60 m. With no pursuer within 35 m it flies
``explore_local``'s waypoint (index 0).

Completion: every evader has at least min(2, N) pursuers within 6 m, 1 round. Rewards:
``simple_tag`` at 70 m per unit, no shaping: each pursuer +10 per colliding (evader,
pursuer) pair over all pursuers (contact below 0.125 u = 8.75 m); the evader -10 per
colliding pursuer and -Σ_axes b(|x|). The evader's return is not in the team mean.

Reference policy (pursuer): ``pursue_target`` on a visible evader (10 - d/100, nearest
first), else ``follow_peer`` on a reported target (5 - d/100), else ``explore_local``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, ClassVar, Final

from aeroweaver_edge.contracts.observation import horizontal_distance
from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest
from aeroweaver_edge.contracts.wire import InboxMessage
from aeroweaver_edge.tasks import policy, scripted
from aeroweaver_edge.tasks.base import NE, Action, Layout, Metrics, TaskDefinition
from aeroweaver_edge.tasks.layout import SPAWN_JITTER_M, spawn_row
from aeroweaver_edge.tasks.spec import RED, RoleSpec, TaskSpec
from aeroweaver_edge.world.kinematics import KinematicWorld

if TYPE_CHECKING:
    import numpy as np

    from aeroweaver_edge.tasks.mpe import MpeRewardModel

EVADER_START: Final = (0.0, 5.0)
EVADER_SPEED_MPS: Final = 15.0
THREAT_M: Final = 35.0
REPULSION_M: Final = 8.0
LIMIT_M: Final = 60.0
CATCH_M: Final = 6.0
CONTACT_M: Final = 3.0

SPEC = TaskSpec(
    name="pursuit_evasion",
    title="Pursuit-evasion",
    summary="pursuers catch an evading drone",
    description=(
        "Pursuer drones chase, intercept and surround a faster intruder or evader drone that "
        "flees from them, closing in from different sides until two pursuers are right next "
        "to it. Pursuers share where the target is with each other."
    ),
    keywords=("pursuit", "chase", "catch", "intercept", "evader", "intruder", "surround"),
    mission_text=(
        "Catch the evading drone: close in with the other pursuers until at least two of you "
        "are within 6 m of it."
    ),
    roles=(
        RoleSpec(
            "pursuer",
            "Close in on the evader with the other pursuers until at least two of you are "
            "within 6 m of it; share where it is.",
            min_count=1,
            nouns="pursuers?|chasers?|hunters?|interceptors?",
        ),
    ),
    role_counts=lambda n: {"pursuer": n},
    team_size=3,
    mpe_module="simple_tag",
    scripted=(
        RoleSpec(
            "evader",
            "Escape the pursuers.",
            min_count=1,
            max_count=1,
            scripted=True,
            team=RED,
            nouns="evaders?|intruders?",
            max_speed_mps=EVADER_SPEED_MPS,
        ),
    ),
    scripted_counts=lambda n: {"evader": 1},
    stable_rounds=1,
    cues=(
        (
            r"\b(?:chase|chasing|pursue|pursuing|pursuit|catch|catching|intercept\w*|hunt\w*)\b"
            r"[^.;]{0,40}\b(?:intruder|evader|runaway|fugitive|quadcopter|drone|target|it)\b",
            2,
        ),
        (r"\bintruder\b|\bevader\b|\bevad(?:e|ing)\b|\bevasion\b|\brunaway\b", 2),
        (r"\bpursuers?\b|\bchase\w*\b|\bpursu\w*\b|\bcatch\b|\bsurround\w*\b|\bintercept\w*\b", 1),
    ),
)


class PursuitPolicy:
    """Pursue a visible evader, else follow a reported one, else explore."""

    def utilities(self, request: DecisionRequest) -> dict[str, float]:
        obs = request.observation
        evaders = [e for e in obs.peers() if e.role == "evader"]

        def rule(c: Candidate) -> float | None:
            if c.skill == "pursue_target":
                t = policy.target(obs, c)
                return -5.0 if t is None else 10.0 - policy.distance_to(obs, t.pos) / 100.0
            if c.skill == "follow_peer":
                return 5.0 - _reported_distance(request, c) / 100.0
            return None

        wants = bool(evaders) or any(c.skill == "follow_peer" for c in request.candidates)
        return policy.score_all(request, rule, wants_something=wants)


def _reported_distance(request: DecisionRequest, c: Candidate) -> float:
    """Distance to the newest position reported for the candidate's target (1e3 if none)."""
    obs = request.observation
    tid = c.params.get("target_id")
    best = 1e3
    newest = -1
    for m in obs.messages:
        if m.kind == "target" and m.body.get("target_id") == tid and m.round > newest:
            n, e = m.body.get("north"), m.body.get("east")
            if isinstance(n, int | float) and isinstance(e, int | float):
                newest = m.round
                best = horizontal_distance(obs.own.pos, (float(n), float(e), 0.0))
    return best


class PursuitEvasion(TaskDefinition):
    spec: ClassVar[TaskSpec] = SPEC
    reference: ClassVar[PursuitPolicy] = PursuitPolicy()

    def setup(self) -> None:
        self._model: MpeRewardModel | None = None
        self._bearing: dict[str, NE] = {}

    @property
    def pursuers(self) -> list[str]:
        return self.of_role("pursuer")

    @property
    def evaders(self) -> list[str]:
        return self.of_role("evader")

    def layout(self, rng: np.random.Generator) -> Layout:
        self._bearing = {}
        spawns = spawn_row(rng, range(self.n_uavs))
        positions = dict(zip(self.pursuers, spawns, strict=True))
        for ev in self.evaders:
            dn, de = (float(v) for v in rng.uniform(-SPAWN_JITTER_M, SPAWN_JITTER_M, 2))
            positions[ev] = (EVADER_START[0] + dn, EVADER_START[1] + de)
        return Layout(positions)

    # -- the evader -----------------------------------------------------------------------

    def scripted_actions(
        self,
        world: KinematicWorld,
        round: int,
        inboxes: Mapping[str, Sequence[InboxMessage]],
    ) -> dict[str, Action]:
        return {ev: self._evade(world, ev, round) for ev in self.evaders}

    def _evade(self, world: KinematicWorld, ev: str, round: int) -> Action:
        me = world.body(ev)
        ctx = scripted.context(me, self.index_in_role(ev), self.name, self.altitude_m)
        if scripted.out_of_bounds(me):
            self._bearing.pop(ev, None)
            return scripted.fly_to(world, me, (0.0, 0.0))
        threats = sorted(
            (math.hypot(b.north - me.north, b.east - me.east), b.id, b)
            for b in (world.body(p) for p in self.pursuers)
        )
        threats = [t for t in threats if t[0] <= THREAT_M]
        if not threats:
            self._bearing.pop(ev, None)
            return scripted.fly_to(world, me, scripted.explore_point(round, ctx))
        _, _, nearest = threats[0]
        en, ee = scripted.escape_from(me, nearest, ctx)
        reach = math.hypot(en - me.north, ee - me.east)
        bearing = _unit(en - me.north, ee - me.east)
        away = _unit(me.north - nearest.north, me.east - nearest.east)
        prev = self._bearing.get(ev)
        if prev is not None and prev[0] * away[0] + prev[1] * away[1] > 0:
            bearing = _unit(prev[0] + bearing[0], prev[1] + bearing[1])
        self._bearing[ev] = bearing
        tn, te = me.north + bearing[0] * reach, me.east + bearing[1] * reach
        for _, _, other in threats[1:]:
            push = _unit(me.north - other.north, me.east - other.east)
            tn, te = tn + REPULSION_M * push[0], te + REPULSION_M * push[1]
        tn = min(max(tn, -LIMIT_M), LIMIT_M)
        te = min(max(te, -LIMIT_M), LIMIT_M)
        return scripted.fly_to(world, me, (tn, te))

    # -- scoring ----------------------------------------------------------------------------

    def _reward_model(self) -> MpeRewardModel:
        if self._model is None:
            from aeroweaver_edge.tasks.mpe import MpeRewardModel

            self._model = MpeRewardModel(
                "simple_tag", make_world_args=(len(self.evaders), len(self.pursuers), 0)
            )
        return self._model

    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        model = self._reward_model()
        order = [*self.pursuers, *self.evaders]  # mpe2: adversaries first, then good agents
        for ent, body in zip(model.world.agents, order, strict=True):
            b = world.body(body)
            model.place(ent, b.north, b.east)
        return dict(zip(order, model.evaluate(), strict=True))

    def _catchers(self, world: KinematicWorld, ev: str, radius: float) -> int:
        e = world.body(ev)
        return sum(
            math.hypot(p.north - e.north, p.east - e.east) <= radius
            for p in (world.body(u) for u in self.pursuers)
        )

    def complete(self, world: KinematicWorld, round: int) -> bool:
        need = min(2, len(self.pursuers))
        return all(self._catchers(world, ev, CATCH_M) >= need for ev in self.evaders)

    def metrics(self, world: KinematicWorld) -> Metrics:
        out = super().metrics(world)
        out["contacts"] = float(sum(self._catchers(world, ev, CONTACT_M) for ev in self.evaders))
        for ev in self.evaders:
            e = world.body(ev)
            out[f"pursuers_within_6m.{ev}"] = float(self._catchers(world, ev, CATCH_M))
            out[f"nearest_pursuer_m.{ev}"] = min(
                math.hypot(p.north - e.north, p.east - e.east)
                for p in (world.body(u) for u in self.pursuers)
            )
        return out


def _unit(n: float, e: float) -> NE:
    d = math.hypot(n, e)
    return (1.0, 0.0) if d < 1e-9 else (n / d, e / d)


TASK = PursuitEvasion
