"""Rewards from the mpe2 scenario functions, evaluated on the kinematic world's state.

The project flies its own physics (MPE's dynamics are meaningless in metres) but takes the
reward *definitions* from ``mpe2`` so the benchmark scores what the authors scored
(docs/notes/mpe-tasks.md). The recipe:

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
``PYGAME_HIDE_SUPPORT_PROMPT`` is set before that import so pygame prints no banner. A daemon
process never builds a reward model, so it never imports mpe2, pygame or scipy.

Scaling (docs/notes/mpe-tasks.md): 70 m per unit, x = north, y = east, arena centre at the
origin, for every task except the two formations, which follow the authors' option A: each
formation is normalised to mpe2's native target size (circle: centre on the centre marker,
R / 0.5 metres per unit; line: centre between the outer slots, span / 1.25 metres per unit).
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from aeroweaver_edge.contracts.defaults import MPE_UNIT_M

__all__ = ["MPE_UNIT_M", "MpeRewardModel", "UnitScale", "scenario_class"]


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
        import numpy as np  # with mpe2: only a process that scores rewards pays for it

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
