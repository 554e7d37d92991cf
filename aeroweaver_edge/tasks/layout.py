"""Seeded layout helpers shared by the task definitions (authors' substrate,
docs/notes/mpe-tasks.md).

* UAV ``i`` spawns at (-38 + 14 i, -34 ± 5) plus ±4 m jitter per axis. The note leaves the
  ±5 unspecified; it alternates, +5 for even i and -5 for odd i, so neighbours start 10 m
  apart in east. Past 8 UAVs the row would leave the arena (north 74 m), so UAV i >= 8
  starts a new row 14 m further east (column i % 8); for N <= 8 this is the authors' formula.
* Each kind of object (landmarks, food, treasures, the formation) moves by one seeded group
  offset, uniform in ±10 m per axis, so the group keeps its shape.
* Extra objects for larger swarms (coverage with N landmarks, ...) are scattered seeded and
  uniformly inside the arena, at least ``min_gap_m`` from every other object.

Every helper draws from the generator it is given, in the order its docstring states, so a
task's layout is a pure function of the seed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Final

from aeroweaver_edge.tasks.base import NE

if TYPE_CHECKING:
    import numpy as np

SPAWN_JITTER_M: Final = 4.0
GROUP_OFFSET_M: Final = 10.0
ROW_LENGTH: Final = 8  # UAVs per spawn row that stay inside the 140 m arena
SCATTER_HALF_M: Final = 55.0  # scattered objects stay inside mpe2's penalty-free 63 m


def spawn_base(i: int) -> NE:
    """Un-jittered spawn point of UAV ``i`` (north, east)."""
    col, row = i % ROW_LENGTH, i // ROW_LENGTH
    stagger = 5.0 if i % 2 == 0 else -5.0
    return -38.0 + 14.0 * col, -34.0 + stagger + 14.0 * row


def group_offset(rng: np.random.Generator) -> NE:
    """One group offset: 2 draws, uniform in ±10 m."""
    n, e = (float(v) for v in rng.uniform(-GROUP_OFFSET_M, GROUP_OFFSET_M, 2))
    return n, e


def shifted(points: Sequence[NE], offset: NE) -> list[NE]:
    return [(n + offset[0], e + offset[1]) for n, e in points]


def spawn_row(rng: np.random.Generator, indices: Sequence[int]) -> list[NE]:
    """Jittered spawn points for the row indices given: 2 draws per index, in one call."""
    jitter = rng.uniform(-SPAWN_JITTER_M, SPAWN_JITTER_M, (len(indices), 2))
    out: list[NE] = []
    for k, i in enumerate(indices):
        n, e = spawn_base(i)
        out.append((n + float(jitter[k, 0]), e + float(jitter[k, 1])))
    return out


def scatter(
    rng: np.random.Generator,
    count: int,
    avoid: Sequence[NE] = (),
    *,
    half_m: float = SCATTER_HALF_M,
    min_gap_m: float = 8.0,
) -> list[NE]:
    """``count`` seeded points uniform in ±``half_m``, each at least ``min_gap_m`` from the
    points in ``avoid`` and from each other. Two draws per attempt; after 200 rejected
    attempts for one point the gap is relaxed by 10 % (dense requests still terminate)."""
    taken = list(avoid)
    out: list[NE] = []
    gap = min_gap_m
    while len(out) < count:
        for _ in range(200):
            n, e = (float(v) for v in rng.uniform(-half_m, half_m, 2))
            if all(math.hypot(n - a, e - b) >= gap for a, b in taken):
                out.append((n, e))
                taken.append((n, e))
                break
        else:
            gap *= 0.9
    return out


__all__ = [
    "GROUP_OFFSET_M",
    "ROW_LENGTH",
    "SPAWN_JITTER_M",
    "group_offset",
    "scatter",
    "shifted",
    "spawn_base",
    "spawn_row",
]
