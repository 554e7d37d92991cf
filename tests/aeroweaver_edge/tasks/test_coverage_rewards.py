"""Coverage reward parity: our adapter vs a hand oracle and vs the native mpe2 env.

Native comparison: ``simple_spread_v3.parallel_env(N=3, local_ratio=0.5)`` is reset, then the
agents' and landmarks' ``p_pos`` are overwritten (in MPE units) and every agent's ``p_vel`` is
zeroed. mpe2's ``World.integrate_state`` moves each entity by its *old* velocity before
applying forces, so a step with no-op actions leaves every position unchanged, and the
rewards the env computes after ``world.step()`` are the rewards *of our state* (checked by
asserting the positions after the step).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import pytest

from aeroweaver_edge.contracts.wire import Entity
from aeroweaver_edge.tasks.coverage import Coverage, SpreadRewards
from aeroweaver_edge.tasks.mpe import UnitScale
from aeroweaver_edge.world.kinematics import KinematicWorld

NE = tuple[float, float]
LANDMARKS: list[NE] = [(-28.0, 24.0), (4.0, 34.0), (32.0, 20.0)]

# Hand-made states (north, east metres): what each exercises is in the comment.
STATES: list[tuple[str, list[NE], list[NE]]] = [
    ("authors' spawn", [(-38.0, -29.0), (-24.0, -39.0), (-10.0, -29.0)], LANDMARKS),
    ("all covered, apart", LANDMARKS, LANDMARKS),
    ("two within 21 m", [(0.0, 0.0), (0.0, 20.9), (50.0, 50.0)], LANDMARKS),
    ("all stacked", [(1.0, 1.0), (2.0, 2.0), (3.0, -3.0)], LANDMARKS),
    ("just outside 21 m", [(0.0, 0.0), (0.0, 21.1), (0.0, 42.2)], LANDMARKS),
    (
        "outside the arena",
        [(90.0, -80.0), (-75.0, 0.0), (0.0, 70.0)],
        [(60.0, 60.0), *LANDMARKS[1:]],
    ),
]


def oracle(agents: Sequence[NE], landmarks: Sequence[NE], unit_m: float = 70.0) -> list[float]:
    """The note's formula, written independently of mpe2:
    ``r_i = -0.5 * Σ_landmarks min_agents d - 0.5 * #{j != i : d(i, j) < 0.30}`` in units."""
    u = [(n / unit_m, e / unit_m) for n, e in agents]
    lm = [(n / unit_m, e / unit_m) for n, e in landmarks]
    cover = sum(min(math.dist(a, p) for a in u) for p in lm)
    out = []
    for i, a in enumerate(u):
        collisions = sum(1 for j, b in enumerate(u) if j != i and math.dist(a, b) < 0.30)
        out.append(-0.5 * cover - 0.5 * collisions)
    return out


@pytest.fixture(scope="module")
def native() -> Iterator[Any]:
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    from mpe2 import simple_spread_v3

    env = simple_spread_v3.parallel_env(N=3, local_ratio=0.5)
    yield env
    env.close()


def native_rewards(env: Any, agents: Sequence[NE], landmarks: Sequence[NE]) -> list[float]:
    env.reset(seed=0)
    world = env.unwrapped.world
    for ent, (n, e) in zip(world.agents, agents, strict=True):
        ent.state.p_pos = np.array([n / 70.0, e / 70.0])
        ent.state.p_vel = np.zeros(2)
    for ent, (n, e) in zip(world.landmarks, landmarks, strict=True):
        ent.state.p_pos = np.array([n / 70.0, e / 70.0])
    _, rewards, _, _, _ = env.step(dict.fromkeys(env.agents, 0))
    after = [float(c) * 70.0 for a in world.agents for c in a.state.p_pos]
    expected = [c for pos in agents for c in pos]
    assert after == pytest.approx(expected, abs=1e-9), "native step moved the agents"
    return [float(rewards[f"agent_{i}"]) for i in range(len(agents))]


@pytest.fixture(scope="module")
def spread3() -> SpreadRewards:
    return SpreadRewards(3, 3)


@pytest.mark.parametrize(
    ("agents", "landmarks"), [s[1:] for s in STATES], ids=[s[0] for s in STATES]
)
def test_matches_hand_oracle(spread3: SpreadRewards, agents: list[NE], landmarks: list[NE]) -> None:
    assert spread3(agents, landmarks) == pytest.approx(oracle(agents, landmarks), abs=1e-12)


@pytest.mark.parametrize(
    ("agents", "landmarks"), [s[1:] for s in STATES], ids=[s[0] for s in STATES]
)
def test_matches_native_env_exactly(
    native: Any, spread3: SpreadRewards, agents: list[NE], landmarks: list[NE]
) -> None:
    assert spread3(agents, landmarks) == native_rewards(native, agents, landmarks)


def test_matches_native_env_on_random_states(native: Any, spread3: SpreadRewards) -> None:
    rng = np.random.default_rng(7)
    for _ in range(25):
        pts = rng.uniform(-75.0, 75.0, (6, 2))
        # Squeeze some states so collisions (< 21 m) are common.
        if rng.random() < 0.5:
            pts[:3] *= 0.2
        agents = [(float(n), float(e)) for n, e in pts[:3]]
        landmarks = [(float(n), float(e)) for n, e in pts[3:]]
        ours = spread3(agents, landmarks)
        assert ours == native_rewards(native, agents, landmarks)
        assert ours == pytest.approx(oracle(agents, landmarks), abs=1e-12)


def test_collision_terms_are_present_in_the_sample() -> None:
    # Guards the parametrisation above: it must exercise 0, 1 and 2 collisions per agent.
    counts: set[int] = set()
    for _, agents, landmarks in STATES:
        base = -0.5 * sum(min(math.dist(a, p) for a in agents) for p in landmarks) / 70.0
        counts.update(round((base - r) / 0.5) for r in oracle(agents, landmarks))
    assert {0, 1, 2} <= counts


def test_n_agents_may_differ_from_n_landmarks() -> None:
    agents = [(-38.0 + 14 * i, -30.0) for i in range(5)]
    assert SpreadRewards(5, 3)(agents, LANDMARKS) == pytest.approx(oracle(agents, LANDMARKS))
    one = [(0.0, 0.0)]
    assert SpreadRewards(1, 3)(one, LANDMARKS) == pytest.approx(oracle(one, LANDMARKS))


def test_scale_and_centre_are_applied() -> None:
    # Arena centred on (100, -50) with 35 m per unit: equivalent to doubling the distances.
    shifted = SpreadRewards(3, 3, scale=UnitScale(35.0, 35.0, 100.0, -50.0))
    agents = [(100.0 + n, -50.0 + e) for n, e in STATES[0][1]]
    landmarks = [(100.0 + n, -50.0 + e) for n, e in LANDMARKS]
    assert shifted(agents, landmarks) == pytest.approx(oracle(STATES[0][1], LANDMARKS, 35.0))


def test_world_is_built_once_and_entities_reused(spread3: SpreadRewards) -> None:
    world = spread3.model.world
    agent_ids = [id(a) for a in world.agents]
    pos_ids = [id(a.state.p_pos) for a in world.agents]
    spread3(*STATES[2][1:])
    spread3(*STATES[3][1:])
    assert [id(a) for a in spread3.model.world.agents] == agent_ids
    assert [id(a.state.p_pos) for a in world.agents] == pos_ids


def test_wrong_sizes_are_rejected(spread3: SpreadRewards) -> None:
    with pytest.raises(ValueError, match="expected 3 agents"):
        spread3(LANDMARKS[:2], LANDMARKS)


def test_coverage_task_rewards_use_world_state(native: Any) -> None:
    task = Coverage(3)
    world = KinematicWorld()
    agents, landmarks = STATES[2][1], STATES[2][2]
    for i, pos in enumerate(agents):
        world.add_uav(f"uav{i}", pos)
    for k, (n, e) in enumerate(landmarks):
        world.add_entity(Entity(id=f"L{k}", kind="landmark", pos=(n, e, -5.0)))
    got = task.rewards(world)
    assert list(got) == ["uav0", "uav1", "uav2"]
    assert list(got.values()) == native_rewards(native, agents, landmarks)
