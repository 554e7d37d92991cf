"""Line formation (mpe2 ``simple_line``): N members take evenly spaced slots on a line
between two endpoint markers.

Layout (draws in this order): one group offset (2) for the formation: endpoint markers
``M0``/``M1`` at (-35, 18) and (35, 18) + offset, slots ``S0..S<N-1>`` evenly from north -28
to +28 at east 18 (+ offset), endpoints of the slot row included; then the members' spawn
jitter (2 each). Past 23 members the 56 m row would put slots closer than 2.5 m, so the row
grows to 2.5 m x (N - 1) (122.5 m for 50 members) and the markers stay 7 m beyond its ends.

Rewards (option A): the line is normalised to mpe2's native length, centre between the
outer slots and span / 1.25 metres per unit (44.8 m for the authors' 56 m), with the
scenario's ``_expected_positions`` overwritten by the normalised slots (mpe2 only sets them
in ``reset_world``); then ``simple_line``'s ``global_reward``: ``-mean_i clip(d_i, 0, 2)`` over
the Hungarian matching. ρ = 0: every member gets that value.
"""

from __future__ import annotations

from typing import Any, ClassVar, Final

from aeroweaver_edge.tasks.base import NE
from aeroweaver_edge.tasks.formation import MEMBER_GOAL, Formation
from aeroweaver_edge.tasks.mpe import MpeRewardModel, UnitScale
from aeroweaver_edge.tasks.spec import RoleSpec, TaskSpec

EAST_M: Final = 18.0
SPAN_M: Final = 56.0
MIN_GAP_M: Final = 2.5
MARKER_BEYOND_M: Final = 7.0
MPE_TOTAL_SEP: Final = 1.25  # simple_line.Scenario.TOTAL_SEP

SPEC = TaskSpec(
    name="line_formation",
    title="Line formation",
    summary="members form an evenly spaced line between two endpoints",
    description=(
        "Member drones line up in a straight row, evenly spaced between two end markers, "
        "each holding its own position in the line."
    ),
    keywords=("line", "row", "straight", "evenly", "spaced", "endpoints", "formation"),
    mission_text=(
        "Line up between the two end markers: every drone takes its own slot on the line and "
        "holds within 3 m of it."
    ),
    roles=(
        RoleSpec(
            "member",
            MEMBER_GOAL.replace("the formation", "the line between the two endpoints"),
            min_count=2,
            facts=("slot",),
            nouns="members?",
        ),
    ),
    role_counts=lambda n: {"member": n},
    team_size=5,
    mpe_module="simple_line",
    cues=(
        (r"\bline (?:up|formation)\b|\bform (?:a |an )?(?:straight )?line\b|\bstraight line\b", 2),
        (r"\bin (?:a |one )?(?:row|line)\b|\bline of\b|\ba row\b", 2),
        (r"\bformation\b|\bend ?points?\b|\bend markers?\b|\bevenly spaced\b|\bline\b", 1),
    ),
)


def span_m(n: int) -> float:
    return max(SPAN_M, MIN_GAP_M * (n - 1))


class LineFormation(Formation):
    spec: ClassVar[TaskSpec] = SPEC

    def shape(self, offset: NE) -> tuple[list[NE], list[NE]]:
        n = self.n_uavs
        span = span_m(n)
        on, oe = offset
        slots = [(-span / 2 + span * k / (n - 1) + on, EAST_M + oe) for k in range(n)]
        end = span / 2 + MARKER_BEYOND_M
        return slots, [(-end + on, EAST_M + oe), (end + on, EAST_M + oe)]

    def scale(self) -> UnitScale:
        (n0, e0), (n1, e1) = self.slots[0], self.slots[-1]
        unit = span_m(self.n_uavs) / MPE_TOTAL_SEP
        return UnitScale(unit, unit, (n0 + n1) / 2, (e0 + e1) / 2)

    def _make_model(self) -> MpeRewardModel:
        return MpeRewardModel("simple_line", make_world_args=(self.n_uavs,), local_ratio=0.0)

    def _prepare(self, model: MpeRewardModel) -> None:
        import numpy as np

        s = model.scale
        scenario: Any = model.scenario
        scenario._expected_positions = [np.array(s.to_units(n, e)) for n, e in self.slots]


TASK = LineFormation
