"""Every task's rewards against mpe2's NATIVE environment, state by state.

For each task and size: build our task and world, draw random states (positions squeezed
often enough that collisions and contacts happen, plus the task's hidden state: goal,
guesses, cargo), and compute our per-body rewards through the task definition itself. Then
build the native ``parallel_env``, reset it, overwrite the same state in MPE units
(computed here from the documented scaling, not by our adapter), zero every velocity and take
one no-op step. mpe2's ``World.integrate_state`` moves entities by their *old* velocity
before applying forces, so the no-op step leaves the positions where we put them (checked)
and the rewards it returns are the rewards of our state. Agents are matched by mpe2's own
names (``adversary_0``, ``agent_0``, ...). Tolerance: 1e-9.
"""

from __future__ import annotations

import math
import os
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from aeroweaver_edge import tasks
from aeroweaver_edge.contracts.wire import Entity
from aeroweaver_edge.tasks.base import TaskDefinition
from aeroweaver_edge.world.kinematics import KinematicWorld

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

UNIT = 70.0
STATES = 60
TOL = 1e-9


def native_env(module: str, **kwargs: Any) -> Any:
    import importlib

    return importlib.import_module(f"mpe2.{module}").parallel_env(**kwargs)


def units(n: float, e: float, unit: float = UNIT, cn: float = 0.0, ce: float = 0.0) -> np.ndarray:
    return np.array([(n - cn) / unit, (e - ce) / unit])


def noop(env: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for a in env.agents:
        space = env.action_space(a)
        out[a] = np.zeros(space.shape, dtype=np.float32) if space.shape else 0
    return out


def step(env: Any, actions: dict[str, Any] | None = None) -> dict[str, float]:
    agents = env.unwrapped.world.agents
    before = [a.state.p_pos.copy() for a in agents]
    for a in agents:
        a.state.p_vel = np.zeros(2)
    acts = noop(env)
    acts.update(actions or {})
    _, rewards, _, _, _ = env.step(acts)
    for a, p in zip(agents, before, strict=True):
        assert np.array_equal(a.state.p_pos, p), "the no-op step moved an agent"
    return {k: float(v) for k, v in rewards.items()}


def move(world: KinematicWorld, body: str, n: float, e: float) -> None:
    b = world.body(body)
    b.north, b.east = n, e


def move_entity(world: KinematicWorld, eid: str, n: float, e: float) -> None:
    old = world.entity(eid)
    world.add_entity(Entity(id=eid, kind=old.kind, pos=(n, e, old.pos[2]), role=old.role))


def ne(world: KinematicWorld, eid: str) -> tuple[float, float]:
    p = world.entity(eid).pos
    return p[0], p[1]


def scatter_bodies(
    rng: np.random.Generator, world: KinematicWorld, bodies: list[str], squeeze: float
) -> None:
    """Random positions in ±75 m; with probability 1/2 squeezed toward a random point."""
    centre = rng.uniform(-50, 50, 2)
    for b in bodies:
        p = rng.uniform(-75.0, 75.0, 2)
        if rng.random() < squeeze:
            p = centre + (p - centre) * 0.12
        move(world, b, float(p[0]), float(p[1]))


@dataclass
class Case:
    name: str
    make: Callable[[], TaskDefinition]
    check: Callable[[TaskDefinition, KinematicWorld, np.random.Generator, Any], int]
    env: Callable[[TaskDefinition], Any]

    @property
    def id(self) -> str:
        return self.name


# --------------------------------------------------------------------------- coverage


def check_coverage(t: Any, world: KinematicWorld, rng: np.random.Generator, env: Any) -> int:
    scatter_bodies(rng, world, t.uav_ids, 0.6)
    for lid in t.landmark_ids:
        n, e = rng.uniform(-70, 70, 2)
        move_entity(world, lid, float(n), float(e))
    ours = t.rewards(world)
    env.reset(seed=0)
    w = env.unwrapped.world
    for i, u in enumerate(t.uav_ids):
        b = world.body(u)
        w.agents[i].state.p_pos = units(b.north, b.east)
    for k, lid in enumerate(t.landmark_ids):
        w.landmarks[k].state.p_pos = units(*ne(world, lid))
    native = step(env)
    for i, u in enumerate(t.uav_ids):
        assert abs(ours[u] - native[f"agent_{i}"]) <= TOL
    return sum(ours[u] != ours[t.uav_ids[0]] for u in t.uav_ids)  # collisions differ per UAV


# --------------------------------------------------------------------------- pursuit


def check_pursuit(t: Any, world: KinematicWorld, rng: np.random.Generator, env: Any) -> int:
    scatter_bodies(rng, world, t.body_ids, 0.7)
    ours = t.rewards(world)
    env.reset(seed=0)
    w = env.unwrapped.world
    names = {a.name: a for a in w.agents}
    for i, p in enumerate(t.pursuers):
        names[f"adversary_{i}"].state.p_pos = units(world.body(p).north, world.body(p).east)
    for i, ev in enumerate(t.evaders):
        names[f"agent_{i}"].state.p_pos = units(world.body(ev).north, world.body(ev).east)
    native = step(env)
    for i, p in enumerate(t.pursuers):
        assert abs(ours[p] - native[f"adversary_{i}"]) <= TOL
    for i, ev in enumerate(t.evaders):
        assert abs(ours[ev] - native[f"agent_{i}"]) <= TOL
    return int(ours[t.pursuers[0]] > 0)


# --------------------------------------------------------------------------- navigation


def check_navigation(t: Any, world: KinematicWorld, rng: np.random.Generator, env: Any) -> int:
    scatter_bodies(rng, world, t.body_ids, 0.5)
    t.goal = t.landmark_ids[int(rng.integers(3))]
    goal_pos = ne(world, t.goal)
    if rng.random() < 0.3:  # a listener right at the goal
        move(world, t.listeners[0], goal_pos[0] + 1.0, goal_pos[1] - 2.0)
    ours = t.rewards(world)
    per_listener = []
    for lid in t.listeners:
        env.reset(seed=0)
        w = env.unwrapped.world
        speaker, listener = w.agents
        s = world.body(t.speaker)
        speaker.state.p_pos = units(s.north, s.east)
        b = world.body(lid)
        listener.state.p_pos = units(b.north, b.east)
        for k, name in enumerate(t.landmark_ids):
            w.landmarks[k].state.p_pos = units(*ne(world, name))
        speaker.goal_a = listener
        speaker.goal_b = w.landmarks[t.landmark_ids.index(t.goal)]
        native = step(env)
        assert native["speaker_0"] == native["listener_0"]
        assert abs(ours[lid] - native["listener_0"]) <= TOL
        per_listener.append(native["listener_0"])
    assert abs(ours[t.speaker] - math.fsum(per_listener) / len(per_listener)) <= TOL
    return 0


# --------------------------------------------------------------------------- crypto


def check_crypto(t: Any, world: KinematicWorld, rng: np.random.Generator, env: Any) -> int:
    t.symbol = int(rng.integers(4))
    t.guesses = {}
    for body in (t.receiver, t.eavesdropper):
        g = int(rng.integers(5))  # 4: no guess yet
        if g < 4:
            assert t.record_guess(body, str(g))
    ours = t.rewards(world)
    env.reset(seed=0)
    w = env.unwrapped.world
    goal = w.agents[0].goal_a  # the landmark every agent shares as its goal
    goal.color = np.eye(4)[t.symbol]

    def say(body: str) -> np.ndarray:
        g = t.guesses.get(body)
        return np.zeros(4, dtype=np.float32) if g is None else np.eye(4, dtype=np.float32)[g]

    native = step(env, {"eve_0": say(t.eavesdropper), "bob_0": say(t.receiver)})
    assert abs(ours[t.eavesdropper] - native["eve_0"]) <= TOL
    assert abs(ours[t.receiver] - native["bob_0"]) <= TOL
    assert abs(ours[t.sender] - native["alice_0"]) <= TOL
    return int(ours[t.sender] != 0)


# --------------------------------------------------------------------------- formations


def check_circle(t: Any, world: KinematicWorld, rng: np.random.Generator, env: Any) -> int:
    cn, ce = t.markers[0]
    for k, body in enumerate(t.members):
        if rng.random() < 0.4:  # near its slot
            sn, se = t.slots[k]
            move(world, body, sn + float(rng.normal(0, 2)), se + float(rng.normal(0, 2)))
        else:
            p = rng.uniform(-75, 75, 2)
            move(world, body, float(p[0]), float(p[1]))
    ours = t.rewards(world)
    env.reset(seed=0)
    w = env.unwrapped.world
    unit = 22.0 / 0.5
    for i, body in enumerate(t.members):
        b = world.body(body)
        w.agents[i].state.p_pos = units(b.north, b.east, unit, cn, ce)
    w.landmarks[0].state.p_pos = units(cn, ce, unit, cn, ce)
    native = step(env)
    for i, body in enumerate(t.members):
        assert abs(ours[body] - native[f"agent_{i}"]) <= TOL
    return 0


def check_line(t: Any, world: KinematicWorld, rng: np.random.Generator, env: Any) -> int:
    (n0, e0), (n1, e1) = t.slots[0], t.slots[-1]
    span = math.hypot(n1 - n0, e1 - e0)
    unit, cn, ce = span / 1.25, (n0 + n1) / 2, (e0 + e1) / 2
    for k, body in enumerate(t.members):
        if rng.random() < 0.4:
            sn, se = t.slots[k]
            move(world, body, sn + float(rng.normal(0, 2)), se + float(rng.normal(0, 2)))
        else:
            p = rng.uniform(-75, 75, 2)
            move(world, body, float(p[0]), float(p[1]))
    ours = t.rewards(world)
    env.reset(seed=0)
    w = env.unwrapped.world
    for i, body in enumerate(t.members):
        b = world.body(body)
        w.agents[i].state.p_pos = units(b.north, b.east, unit, cn, ce)
    for k, (n, e) in enumerate(t.markers):
        w.landmarks[k].state.p_pos = units(n, e, unit, cn, ce)
    env.unwrapped.scenario._expected_positions = [units(n, e, unit, cn, ce) for n, e in t.slots]
    native = step(env)
    for i, body in enumerate(t.members):
        assert abs(ours[body] - native[f"agent_{i}"]) <= TOL
    return 0


# --------------------------------------------------------------------------- world comm


def check_world(t: Any, world: KinematicWorld, rng: np.random.Generator, env: Any) -> int:
    scatter_bodies(rng, world, t.body_ids, 0.7)
    for f in t.foragers:
        if rng.random() < 0.3:  # on a food source
            n, e = ne(world, t.food_ids[int(rng.integers(2))])
            move(world, f, n + float(rng.normal(0, 3)), e + float(rng.normal(0, 3)))
    ours = t.rewards(world)
    env.reset(seed=0)
    w = env.unwrapped.world
    names = {a.name: a for a in w.agents}
    advs = t.adversaries
    names["leadadversary_0"].state.p_pos = units(
        world.body(advs[0]).north, world.body(advs[0]).east
    )
    for i, p in enumerate(advs[1:]):
        names[f"adversary_{i}"].state.p_pos = units(world.body(p).north, world.body(p).east)
    for i, f in enumerate(t.foragers):
        names[f"agent_{i}"].state.p_pos = units(world.body(f).north, world.body(f).east)
    for k, fid in enumerate(t.food_ids):
        w.food[k].state.p_pos = units(*ne(world, fid))
    for k, wid in enumerate(t.forest_ids):
        w.forests[k].state.p_pos = units(*ne(world, wid))
    native = step(env)
    assert abs(ours[advs[0]] - native["leadadversary_0"]) <= TOL
    for i, p in enumerate(advs[1:]):
        assert abs(ours[p] - native[f"adversary_{i}"]) <= TOL
    for i, f in enumerate(t.foragers):
        assert abs(ours[f] - native[f"agent_{i}"]) <= TOL
    return 0


# --------------------------------------------------------------------------- collection


def check_collection(t: Any, world: KinematicWorld, rng: np.random.Generator, env: Any) -> int:
    for c in t.collectors:
        t.cargo[c] = str(rng.choice(["", *t.colours]))
    for tid in t.treasure_ids:
        if rng.random() < 0.25:
            t.alive[tid] = False
            world.remove_entity(tid)
    scatter_bodies(rng, world, t.body_ids, 0.3)
    live = [tid for tid in t.treasure_ids if t.alive[tid]]
    for c in t.collectors:
        r = rng.random()
        if r < 0.35 and live:  # touching a treasure
            n, e = t.treasure_pos[live[int(rng.integers(len(live)))]]
            move(world, c, n + float(rng.normal(0, 2.5)), e + float(rng.normal(0, 2.5)))
        elif r < 0.7:  # near a deposit
            d = world.body(t.deposits[int(rng.integers(len(t.deposits)))])
            move(world, c, d.north + float(rng.normal(0, 4)), d.east + float(rng.normal(0, 4)))
    state = {
        "cargo": dict(t.cargo),
        "alive": dict(t.alive),
        "pos": {b: (world.body(b).north, world.body(b).east) for b in t.body_ids},
    }
    t.after_step(world)
    ours = t.rewards(world)
    env.reset(seed=0)
    w = env.unwrapped.world
    names = {a.name: a for a in w.agents}
    for i, c in enumerate(t.collectors):
        a = names[f"collector_{i}"]
        a.state.p_pos = units(*state["pos"][c])
        cargo = state["cargo"][c]
        a.holding = t.colours.index(cargo) if cargo else None
    for i, d in enumerate(t.deposits):
        names[f"deposit_{i}"].state.p_pos = units(*state["pos"][d])
    for k, tid in enumerate(t.treasure_ids):
        lm = w.landmarks[k]
        lm.type = t.colours.index(t.treasure_colour[tid])
        lm.respawn_prob = -1.0
        lm.alive = state["alive"][tid]
        lm.state.p_pos = units(*t.treasure_pos[tid]) if lm.alive else np.array([-999.0, -999.0])
    native = step(env)
    for i, c in enumerate(t.collectors):
        assert abs(ours[c] - native[f"collector_{i}"]) <= TOL
        holding = names[f"collector_{i}"].holding
        assert t.cargo[c] == ("" if holding is None else t.colours[holding])
    for i, d in enumerate(t.deposits):
        assert abs(ours[d] - native[f"deposit_{i}"]) <= TOL
    return int(t.picked + t.delivered > 0)  # a pickup or a delivery happened in this step


# --------------------------------------------------------------------------- concealment


def check_concealment(t: Any, world: KinematicWorld, rng: np.random.Generator, env: Any) -> int:
    scatter_bodies(rng, world, t.body_ids, 0.4)
    t.goal = t.landmark_ids[int(rng.integers(len(t.landmark_ids)))]
    ours = t.rewards(world)
    env.reset(seed=0)
    w = env.unwrapped.world
    names = {a.name: a for a in w.agents}
    goal = w.landmarks[int(rng.integers(len(w.landmarks)))]
    goal.state.p_pos = units(*ne(world, t.goal))
    for a in w.agents:
        a.goal_a = goal
    adv = t.adversaries[0]
    names["adversary_0"].state.p_pos = units(world.body(adv).north, world.body(adv).east)
    for i, u in enumerate(t.informed):
        names[f"agent_{i}"].state.p_pos = units(world.body(u).north, world.body(u).east)
    native = step(env)
    assert abs(ours[adv] - native["adversary_0"]) <= TOL
    for i, u in enumerate(t.informed):
        assert abs(ours[u] - native[f"agent_{i}"]) <= TOL
    return 0


def _task(name: str, n: int) -> Callable[[], TaskDefinition]:
    return lambda: tasks.create(name, n)


def _n(t: TaskDefinition, role: str) -> int:
    return len(t.of_role(role))


CASES = [
    Case("coverage-3", _task("coverage", 3), check_coverage,
         lambda t: native_env("simple_spread_v3", N=3, local_ratio=0.5)),
    Case("coverage-7", _task("coverage", 7), check_coverage,
         lambda t: native_env("simple_spread_v3", N=7, local_ratio=0.5)),
    Case("pursuit-3", _task("pursuit_evasion", 3), check_pursuit,
         lambda t: native_env("simple_tag_v3", num_good=1, num_adversaries=3, num_obstacles=0)),
    Case("pursuit-6", _task("pursuit_evasion", 6), check_pursuit,
         lambda t: native_env("simple_tag_v3", num_good=1, num_adversaries=6, num_obstacles=0)),
    Case("navigation-2", _task("guided_navigation", 2), check_navigation,
         lambda t: native_env("simple_speaker_listener_v4", continuous_actions=True)),
    Case("navigation-4", _task("guided_navigation", 4), check_navigation,
         lambda t: native_env("simple_speaker_listener_v4", continuous_actions=True)),
    Case("crypto", _task("private_communication", 2), check_crypto,
         lambda t: native_env("simple_crypto_v3", continuous_actions=True)),
    Case("circle-5", _task("circular_formation", 5), check_circle,
         lambda t: native_env("simple_formation_v1", N=5)),
    Case("circle-9", _task("circular_formation", 9), check_circle,
         lambda t: native_env("simple_formation_v1", N=9)),
    Case("line-5", _task("line_formation", 5), check_line,
         lambda t: native_env("simple_line_v1", N=5)),
    Case("line-30", _task("line_formation", 30), check_line,
         lambda t: native_env("simple_line_v1", N=30)),
    Case("world-3", _task("world_communication", 3), check_world,
         lambda t: native_env("simple_world_comm_v3", num_good=2, num_adversaries=3,
                              num_obstacles=0, num_food=2, num_forests=2)),
    Case("world-6", _task("world_communication", 6), check_world,
         lambda t: native_env("simple_world_comm_v3", num_good=2, num_adversaries=6,
                              num_obstacles=0, num_food=2, num_forests=2)),
    Case("collection-4", _task("collection_delivery", 4), check_collection,
         lambda t: native_env("collect_treasure_v1", num_collectors=2, num_deposits=2,
                              num_treasures=4)),
    Case("collection-2", _task("collection_delivery", 2), check_collection,
         lambda t: native_env("collect_treasure_v1", num_collectors=1, num_deposits=1,
                              num_treasures=4)),
    Case("collection-8", _task("collection_delivery", 8), check_collection,
         lambda t: native_env("collect_treasure_v1", num_collectors=6, num_deposits=2,
                              num_treasures=6)),
    Case("concealment-2", _task("goal_concealment", 2), check_concealment,
         lambda t: native_env("simple_adversary_v3", N=2)),
    Case("concealment-5", _task("goal_concealment", 5), check_concealment,
         lambda t: native_env("simple_adversary_v3", N=5)),
]  # fmt: skip


@pytest.fixture(params=CASES, ids=[c.id for c in CASES])
def case(request: pytest.FixtureRequest) -> Iterator[tuple[Case, TaskDefinition, Any]]:
    c: Case = request.param
    t = c.make()
    env = c.env(t)
    yield c, t, env
    env.close()


def test_rewards_equal_the_native_environment(case: tuple[Case, TaskDefinition, Any]) -> None:
    c, t, env = case
    rng = np.random.default_rng(zlib.crc32(c.name.encode()))
    interesting = 0
    for i in range(STATES):  # a fresh episode each time (goal, cargo, live treasures)
        world = t.build_world(np.random.default_rng(i))
        interesting += c.check(t, world, rng, env)
    # Each case must also reach the branches that matter (collisions, captures, pickups...).
    if c.name.startswith(("coverage", "pursuit", "collection")):
        assert interesting > 0, f"{c.name}: no state exercised collisions or contacts"


def test_every_task_has_a_parity_case() -> None:
    covered = {c.make().name for c in CASES}
    assert covered == set(tasks.TASK_NAMES)


def test_the_cases_exercise_contacts_and_crypto_outcomes() -> None:
    """Direct checks that the sampled regimes exist: a pursuit capture and a food contact."""
    t: Any = tasks.create("pursuit_evasion", 3)
    world = t.build_world(np.random.default_rng(1))
    ev = world.body(t.evaders[0])
    move(world, t.pursuers[0], ev.north + 5.0, ev.east)  # 5 m < 8.75 m contact
    r = t.rewards(world)
    assert r[t.pursuers[0]] == r[t.pursuers[1]] == 10.0
    assert r[t.evaders[0]] <= -10.0
