"""Circular formation (mpe2 ``simple_formation``): N members take evenly spaced slots on a
circle around a centre marker.

Layout (draws in this order): one group offset (2) for the formation, whose centre marker
``M0`` is at (0, 12) + offset; slot ``S<k>`` sits 22 m from it at bearing 2πk/N (from north
toward east); then the members' spawn jitter (2 each, spawn row 0..N-1). With 50 members
neighbouring slots are still 2.8 m apart (above the 2 m separation the safety gate keeps).

Rewards (option A): the circle is normalised to mpe2's native target radius, centre on the
centre marker and 22 / 0.5 = 44 m per unit, then ``simple_formation``'s ``global_reward``:
``-mean_i clip(d_i, 0, 2)`` over the Hungarian matching of members to the N ideal points at
radius 0.5 (anchored at the smallest polar angle, x = north, y = east). ρ = 0: every member
gets that value. See ``tasks.formation`` for slots, completion and the policy.
"""

from __future__ import annotations

import math
from typing import ClassVar, Final

from aeroweaver_edge.tasks.base import NE
from aeroweaver_edge.tasks.formation import MEMBER_GOAL, Formation
from aeroweaver_edge.tasks.mpe import MpeRewardModel, UnitScale
from aeroweaver_edge.tasks.spec import RoleSpec, TaskSpec

CENTRE: Final = (0.0, 12.0)
RADIUS_M: Final = 22.0
MPE_TARGET_RADIUS: Final = 0.5  # simple_formation.Scenario.TARGET_RADIUS

SPEC = TaskSpec(
    name="circular_formation",
    title="Circular formation",
    summary="members form a circle around a centre marker",
    description=(
        "Member drones arrange themselves in a ring, evenly spaced on a circle around a "
        "centre marker, each holding its own position on the circle around the middle point."
    ),
    keywords=("circle", "ring", "circular", "formation", "around", "centre", "encircle"),
    mission_text=(
        "Form a circle around the centre marker: every drone takes its own slot on the circle "
        "and holds within 3 m of it."
    ),
    roles=(
        RoleSpec(
            "member",
            MEMBER_GOAL.replace("the formation", "the circle around the centre marker"),
            min_count=2,
            facts=("slot",),
            nouns="members?",
        ),
    ),
    role_counts=lambda n: {"member": n},
    team_size=5,
    mpe_module="simple_formation",
    cues=(
        (r"\bcircle\b|\bcircular\b|\bring\b|\bencircl\w*\b", 2),
        (r"\bformation\b|\baround the (?:centre|center|middle)\b", 1),
    ),
)


class CircularFormation(Formation):
    spec: ClassVar[TaskSpec] = SPEC

    def shape(self, offset: NE) -> tuple[list[NE], list[NE]]:
        cn, ce = CENTRE[0] + offset[0], CENTRE[1] + offset[1]
        n = self.n_uavs
        slots = [
            (
                cn + RADIUS_M * math.cos(2 * math.pi * k / n),
                ce + RADIUS_M * math.sin(2 * math.pi * k / n),
            )
            for k in range(n)
        ]
        return slots, [(cn, ce)]

    def scale(self) -> UnitScale:
        unit = RADIUS_M / MPE_TARGET_RADIUS
        cn, ce = self.markers[0]
        return UnitScale(unit, unit, cn, ce)

    def _make_model(self) -> MpeRewardModel:
        return MpeRewardModel("simple_formation", make_world_args=(self.n_uavs,), local_ratio=0.0)


TASK = CircularFormation
