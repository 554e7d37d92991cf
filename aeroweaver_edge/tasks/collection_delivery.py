"""Collection-delivery (mpe2 ``collect_treasure``): collectors pick up treasures and deliver
each to the deposit of its colour; the deposits are UAVs too.

Bodies: C >= 1 collectors (private fact ``cargo``: the colour they carry, "" when empty),
``deposit_red`` and, when there are three or more UAVs, ``deposit_blue``. Treasures are
entities of kind ``"treasure"`` whose ``role`` is their colour: the authors' four at
(-25, 0) red, (20, 4) blue, (-8, 22) red, (30, 30) blue, and for more than four collectors
one more per collector, scattered, colours alternating. With only a red deposit every
treasure is red (mpe2 has one treasure type per deposit).

Layout (draws in this order): one group offset (2) for the authors' treasures; spawn jitter
(2 each) of the UAVs at spawn rows 0..N-1; the extra treasures (``layout.scatter``).

Pickup and delivery are mpe2's own ``post_step`` run on our state after every physics step
(a collector picks up a live treasure on contact, below 0.075 u = 5.25 m; it delivers on
contact with the matching deposit, below 0.125 u = 8.75 m), with respawn switched off as in
the authors' runtime: a picked treasure leaves the world for the rest of the episode. The
reward therefore pays +5 once per pickup and once per delivery (mpe2 1.1.1's cached global
reward), never per round a contact lasts. Collector: global - 5 per other collector within
0.10 u (7 m) - 0.1 d(nearest live treasure) when empty or - 0.1 d(nearest matching deposit)
when loaded. Deposit: global - 0.1 d(nearest collector carrying its colour), else - 0.1
d(collectors' centroid). Completion: every treasure delivered (1 round).

Reference policy: an empty collector takes the treasure the greedy nearest assignment
(over the collectors it knows of) gives it, a loaded one delivers to the matching deposit,
otherwise it explores; a deposit meets the nearest collector that announced its colour,
otherwise it holds.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar, Final

from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest
from aeroweaver_edge.contracts.wire import Entity
from aeroweaver_edge.tasks import policy
from aeroweaver_edge.tasks.base import Layout, Metrics, TaskDefinition
from aeroweaver_edge.tasks.layout import group_offset, scatter, shifted, spawn_row
from aeroweaver_edge.tasks.spec import RoleSpec, TaskSpec
from aeroweaver_edge.world.kinematics import KinematicWorld

if TYPE_CHECKING:
    import numpy as np

    from aeroweaver_edge.tasks.mpe import MpeRewardModel

TREASURES: Final = (
    ((-25.0, 0.0), "red"),
    ((20.0, 4.0), "blue"),
    ((-8.0, 22.0), "red"),
    ((30.0, 30.0), "blue"),
)
COLOURS: Final = ("red", "blue")
DEAD: Final = -999.0  # where mpe2 parks a picked treasure


def _counts(n: int) -> dict[str, int]:
    if n >= 3:
        return {"collector": n - 2, "deposit_red": 1, "deposit_blue": 1}
    return {"collector": n - 1, "deposit_red": 1}


SPEC = TaskSpec(
    name="collection_delivery",
    title="Collection-delivery",
    summary="collectors pick up treasures and deliver them to the matching deposit",
    description=(
        "Collector drones pick up treasures scattered over the area, carry them and drop "
        "them off at the deposit of the same colour; the deposits are drones that move to "
        "meet loaded collectors. Gather, fetch, transport and deliver the cargo."
    ),
    keywords=("treasure", "collect", "deliver", "deposit", "pick up", "carry", "cargo"),
    mission_text=(
        "Collect the treasures and deliver each one to the deposit of its colour; avoid "
        "crowding other collectors."
    ),
    roles=(
        RoleSpec(
            "collector",
            "Pick up an available treasure and deliver it to the deposit of its colour; avoid "
            "crowding other collectors.",
            min_count=1,
            facts=("cargo",),
            nouns="collectors?|carriers?|gatherers?",
        ),
        RoleSpec(
            "deposit_red",
            "Move toward collectors carrying red treasure to take their delivery.",
            min_count=1,
            max_count=1,
        ),
        RoleSpec(
            "deposit_blue",
            "Move toward collectors carrying blue treasure to take their delivery.",
            min_count=0,
            max_count=1,
        ),
    ),
    role_counts=_counts,
    team_size=4,
    mpe_module="collect_treasure",
    stable_rounds=1,
    cues=(
        (r"\btreasures?\b", 2),
        (r"\bdeliver\w*\b|\bdeposits?\b|\bdepots?\b", 2),
        (r"\bcollect(?:s|ed|ing|ors?)?\b", 2),
        (r"\bpick (?:up|them up)\b|\bdrop(?: \w+)? (?:off|at)\b|\bcarr(?:y|ies|iers?)\b", 1),
    ),
)


class CollectionPolicy:
    def utilities(self, request: DecisionRequest) -> dict[str, float]:
        obs = request.observation
        treasures = {e.id: e.pos for e in obs.of_kind("treasure")}
        collectors = policy.known_positions(obs, roles={"collector"})
        owner = policy.greedy_assignment(collectors, treasures)

        def rule(c: Candidate) -> float | None:
            t = policy.target(obs, c)
            d = 1.0 if t is None else policy.distance_to(obs, t.pos) / 100.0
            if c.skill == "collect_treasure":
                holder = owner.get(t.id) if t is not None else None
                return (10.0 if holder == obs.uav else 5.0 if holder is None else 0.0) - d
            if c.skill in ("deliver_treasure", "meet_collector"):
                return 10.0 - d
            if c.skill == "explore_local" and request.role != "collector":
                return -5.0  # a deposit waits for a loaded collector
            return None

        wants = any(
            c.skill in ("collect_treasure", "deliver_treasure", "meet_collector")
            for c in request.candidates
        )
        return policy.score_all(request, rule, wants_something=wants)


class CollectionDelivery(TaskDefinition):
    spec: ClassVar[TaskSpec] = SPEC
    reference: ClassVar[CollectionPolicy] = CollectionPolicy()

    def setup(self) -> None:
        self.colours = COLOURS[: len(self.deposits)]
        n_treasures = max(len(TREASURES), len(self.collectors))
        self.treasure_ids = [f"T{k}" for k in range(n_treasures)]
        self.treasure_colour: dict[str, str] = {}
        self.treasure_pos: dict[str, tuple[float, float]] = {}
        self.alive: dict[str, bool] = {}
        self.cargo: dict[str, str] = {}
        self.picked = 0
        self.delivered = 0
        self._model: MpeRewardModel | None = None

    @property
    def collectors(self) -> list[str]:
        return self.of_role("collector")

    @property
    def deposits(self) -> list[str]:
        """Red first: deposit k accepts treasure type k (mpe2's ``d_i``)."""
        return [*self.of_role("deposit_red"), *self.of_role("deposit_blue")]

    def layout(self, rng: np.random.Generator) -> Layout:
        authors = shifted([p for p, _ in TREASURES], group_offset(rng))
        spawns = spawn_row(rng, range(self.n_uavs))
        extra = scatter(rng, len(self.treasure_ids) - len(authors), authors)
        points = authors + extra
        colours = [c for _, c in TREASURES] + [COLOURS[k % 2] for k in range(len(extra))]
        if len(self.colours) == 1:
            colours = [self.colours[0]] * len(points)
        self.treasure_pos = dict(zip(self.treasure_ids, points, strict=True))
        self.treasure_colour = dict(zip(self.treasure_ids, colours, strict=True))
        self.alive = dict.fromkeys(self.treasure_ids, True)
        self.cargo = dict.fromkeys(self.collectors, "")
        self.picked = self.delivered = 0
        self._model = None
        down = -self.altitude_m
        entities = [
            Entity(id=t, kind="treasure", pos=(n, e, down), role=self.treasure_colour[t])
            for t, (n, e) in self.treasure_pos.items()
        ]
        return Layout(dict(zip(self.uav_ids, spawns, strict=True)), entities)

    def facts(self, world: KinematicWorld, body: str) -> dict[str, str]:
        return {"cargo": self.cargo[body]} if body in self.cargo else {}

    # -- mpe2 state ------------------------------------------------------------------------

    def _reward_model(self) -> MpeRewardModel:
        if self._model is None:
            from aeroweaver_edge.tasks.mpe import MpeRewardModel

            self._model = MpeRewardModel(
                "collect_treasure",
                make_world_args=(len(self.collectors), len(self.deposits), len(self.treasure_ids)),
            )
            import numpy as np

            world: Any = self._model.world
            world.np_random = np.random.default_rng(0)  # post_step's respawn draws; unused
            for lm, tid in zip(world.landmarks, self.treasure_ids, strict=True):
                lm.respawn_prob = -1.0  # never respawn (uniform() <= -1 is impossible)
                lm.type = self.colours.index(self.treasure_colour[tid])
                lm.color = world.treasure_colors[lm.type].copy()
        return self._model

    def _sync_to_mpe(self, world: KinematicWorld) -> Any:
        model = self._reward_model()
        mw: Any = model.world
        for ent, body in zip(mw.agents, [*self.collectors, *self.deposits], strict=True):
            b = world.body(body)
            model.place(ent, b.north, b.east)
            if body in self.cargo:
                ent.holding = self.colours.index(self.cargo[body]) if self.cargo[body] else None
        for lm, tid in zip(mw.landmarks, self.treasure_ids, strict=True):
            lm.alive = self.alive[tid]
            if lm.alive:
                model.place(lm, *self.treasure_pos[tid])
            else:
                lm.state.p_pos[0] = lm.state.p_pos[1] = DEAD
        return mw

    def after_step(self, world: KinematicWorld) -> None:
        """mpe2's pickup and delivery on the new state; our cargo, treasures and counts follow."""
        mw = self._sync_to_mpe(world)
        model = self._reward_model()
        scenario: Any = model.scenario
        scenario.post_step(mw)
        self.picked += round(scenario._cached_global_collecting / 5.0)
        self.delivered += round(scenario._cached_global_deposit / 5.0)
        for ent, body in zip(mw.agents, self.collectors, strict=False):
            self.cargo[body] = "" if ent.holding is None else self.colours[ent.holding]
        for lm, tid in zip(mw.landmarks, self.treasure_ids, strict=True):
            if self.alive[tid] and not lm.alive:
                self.alive[tid] = False
                world.remove_entity(tid)

    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        """Per-agent rewards with the pickups and deliveries of the last ``after_step``."""
        model = self._reward_model()
        order = [*self.collectors, *self.deposits]
        mw: Any = model.world
        for ent, body in zip(mw.agents, order, strict=True):
            b = world.body(body)
            model.place(ent, b.north, b.east)
        return dict(zip(order, model.evaluate(), strict=True))

    def complete(self, world: KinematicWorld, round: int) -> bool:
        return self.delivered >= len(self.treasure_ids)

    def metrics(self, world: KinematicWorld) -> Metrics:
        out = super().metrics(world)
        out["picked"] = float(self.picked)
        out["delivered"] = float(self.delivered)
        out["carrying"] = float(sum(bool(c) for c in self.cargo.values()))
        return out


TASK = CollectionDelivery
