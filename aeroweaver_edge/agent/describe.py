"""The textual observation: what the LLM reads and what experience retrieval matches on.

Numbers are rounded (metres to 5 m) so that alike states share tokens.
"""

from __future__ import annotations

import math

from aeroweaver_edge.observation import Observation, horizontal_distance
from aeroweaver_edge.wire import Vec3

_COMPASS = ("N", "NE", "E", "SE", "S", "SW", "W", "NW")


def _bearing(src: Vec3, dst: Vec3) -> str:
    ang = math.degrees(math.atan2(dst[1] - src[1], dst[0] - src[0])) % 360.0
    return _COMPASS[int((ang + 22.5) // 45) % 8]


def _m(x: float) -> int:
    return int(5 * round(x / 5))


def describe(obs: Observation) -> str:
    pos = obs.own.pos
    speed = math.hypot(obs.own.vel[0], obs.own.vel[1])
    lines = [
        f"round {obs.round}; position north {_m(pos[0])} m east {_m(pos[1])} m; "
        f"speed {round(speed)} m/s",
    ]
    for e in sorted(obs.entities, key=lambda e: (e.kind, e.id)):
        d = horizontal_distance(pos, e.pos)
        role = f" ({e.role})" if e.role else ""
        # The id comes right before the distance so similar states share "<id>~<metres>".
        lines.append(f"{e.kind}{role} {e.id}: {_m(d)} m {_bearing(pos, e.pos)}")
    if not obs.entities:
        lines.append("nothing within sensing range")
    return "\n".join(lines)
