"""Rewards from the mpe2 scenario functions, evaluated on the kinematic world's state.

The project flies its own physics (MPE's dynamics are meaningless in metres) but takes the
reward *definitions* from ``mpe2`` so the benchmark scores what the authors scored
(notes/mpe-tasks.md). The recipe:

* build the scenario's world once (``make_world`` + ``reset_world``; the reset initialises
  colours, velocities and comm vectors that mpe2 refuses to read while unset);
* before each evaluation, overwrite ``state.p_pos`` *in place* with our positions converted
  to MPE units (x = north, y = east, ``(p_m - centre) / 70``);
* combine exactly as ``SimpleEnv._execute_world_step`` in mpe2 1.1.1 does:
  ``r_i = global * (1 - ρ) + reward(i) * ρ`` when the env has a ``local_ratio`` ρ, else
  ``reward(i)`` — same operation order, so results are bit-identical to the native env.

Entities are never re-created or deep-copied: mpe2's collision loops compare agents by
identity (``a != agent``), and rebuilding worlds per call would cost ~100 µs each.

mpe2 is imported lazily (the first scenario import pulls pygame and takes ~0.3 s), and
``PYGAME_HIDE_SUPPORT_PROMPT`` is set before that import so pygame prints no banner.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np

MPE_UNIT_M: Final = 70.0
"""Metres per MPE unit: the 140 m arena maps onto [-1, 1]², where MPE resets live."""


def _import_mpe2(module: str) -> Any:
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    return importlib.import_module(f"mpe2.{module}.{module}")


def scenario_class(module: str) -> Any:
    """The ``Scenario`` class of ``mpe2.<module>.<module>`` (e.g. ``"simple_spread"``)."""
    return _import_mpe2(module).Scenario


@dataclass(frozen=True, slots=True)
class UnitScale:
    """Metres <-> MPE units. x = north, y = east; the arena centre maps to the origin."""

    north_m: float = MPE_UNIT_M
    east_m: float = MPE_UNIT_M
    centre_north_m: float = 0.0
    centre_east_m: float = 0.0

    def to_units(self, north: float, east: float) -> tuple[float, float]:
        x = (north - self.centre_north_m) / self.north_m
        y = (east - self.centre_east_m) / self.east_m
        return x, y


class MpeRewardModel:
    """One mpe2 scenario world, built once, that scores our state on demand.

    ``world.agents`` and ``world.landmarks`` are the mpe2 objects; task adapters write
    positions with :meth:`place` (and anything else a scenario needs, e.g. goals or comm
    vectors, directly on ``world``) and then call :meth:`evaluate`.
    """

    def __init__(
        self,
        module: str,
        *,
        make_world_args: Sequence[Any] = (),
        scenario_kwargs: dict[str, Any] | None = None,
        local_ratio: float | None = None,
        scale: UnitScale | None = None,
        seed: int = 0,
    ) -> None:
        if local_ratio is not None and not 0.0 <= local_ratio <= 1.0:
            raise ValueError(f"local_ratio must be in [0, 1], got {local_ratio!r}")
        self.module = module
        self.local_ratio = local_ratio
        self.scale = scale or UnitScale()
        self.scenario: Any = scenario_class(module)(**(scenario_kwargs or {}))
        self.world: Any = self.scenario.make_world(*make_world_args)
        self.reset(seed)

    def reset(self, seed: int = 0) -> None:
        """Re-run ``reset_world`` (initialises every attribute mpe2 insists on reading).

        Positions are overwritten by :meth:`place` before scoring, so the seed only matters
        for scenarios whose reset draws hidden information (goals); tasks overwrite those too.
        """
        self.scenario.reset_world(self.world, np.random.default_rng(seed))

    def place(self, entity: Any, north: float, east: float) -> None:
        """Write our metric position into an mpe2 entity, in place (no new array)."""
        x, y = self.scale.to_units(north, east)
        p = entity.state.p_pos
        p[0] = x
        p[1] = y

    def evaluate(self) -> list[float]:
        """Per-agent rewards in ``world.agents`` order, combined as mpe2's ``SimpleEnv`` does."""
        scenario, world, rho = self.scenario, self.world, self.local_ratio
        if rho is None:
            return [float(scenario.reward(a, world)) for a in world.agents]
        global_reward = float(scenario.global_reward(world))
        return [
            global_reward * (1 - rho) + float(scenario.reward(a, world)) * rho for a in world.agents
        ]


class SpreadRewards:
    """``simple_spread`` (coverage) rewards: ``0.5 * global + 0.5 * collisions_i`` at ρ = 0.5.

    ``global = -Σ_landmarks min_agents d`` and the local term is ``-1`` per other agent closer
    than 0.30 units (21 m). Constructed with mpe2 1.1.1's defaults (``curriculum=False``:
    the collision penalty is always on; ``CAPTURE_RADIUS`` only affects the optional
    ``terminate_on_success`` and never the reward), matching ``simple_spread_v3`` defaults.

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
        self.model = model
        self.n_agents = n_agents
        self.n_landmarks = n_landmarks

    def __call__(
        self,
        agents: Sequence[tuple[float, float]],
        landmarks: Sequence[tuple[float, float]],
    ) -> list[float]:
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
