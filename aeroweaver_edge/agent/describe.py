"""The textual observation: what the LLM reads each round and the base of the state text that
experience retrieval matches on (``agent.state_text``).

Numbers are rounded (metres to 5 m) so that alike states share tokens, and the text is
compact: small models spend one token per digit. In an entity line the id comes right
before the distance, so the retrieval tokeniser pairs them (``uav1~10``).
"""

from __future__ import annotations

import math
from typing import Any

from aeroweaver_edge.observation import Observation, horizontal_distance
from aeroweaver_edge.wire import Entity, Vec3

_COMPASS = ("N", "NE", "E", "SE", "S", "SW", "W", "NW")


def bearing(src: Vec3 | tuple[float, float], dst: Vec3 | tuple[float, float]) -> str:
    """Compass point (8 sectors) from ``src`` to ``dst``, north = +x, east = +y."""
    ang = math.degrees(math.atan2(dst[1] - src[1], dst[0] - src[0])) % 360.0
    return _COMPASS[int((ang + 22.5) // 45) % 8]


def metres5(x: float) -> int:
    """Metres rounded to 5 m."""
    return int(5 * round(x / 5))


HUGE = 1e9
"""A reported number this large is no measurement here; its digits would only cost tokens
and blur retrieval, so the renderers abbreviate it."""

MAX_PLACE_M = 100_000.0
"""A peer-reported position farther out than this (on either axis) is not a place: no arena
is that large, and a hostile ``1.7e308`` would overflow the distance."""


def _coordinate(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if abs(value) <= MAX_PLACE_M else None  # also rejects NaN


def pop_place(body: dict[str, Any], own: Vec3 | tuple[float, float]) -> str | None:
    """``"<d> m <bearing>"`` from ``own`` to the body's (north, east), which it removes from
    ``body``; ``None`` (body untouched) when that is not a place: not two numbers, not
    finite, or beyond ``MAX_PLACE_M``."""
    n, e = _coordinate(body.get("north")), _coordinate(body.get("east"))
    if n is None or e is None:
        return None
    del body["north"], body["east"]
    d = math.hypot(n - own[0], e - own[1])
    return f"{metres5(d)} m {bearing(own, (n, e))}"


def _entity_line(e: Entity, pos: Vec3) -> str:
    d = horizontal_distance(pos, e.pos)
    if e.kind == "uav":  # the id says it is a UAV; the role says what it does
        what = f"{e.role or 'uav'} {e.id}"
    else:
        what = f"{e.kind} ({e.role}) {e.id}" if e.role else f"{e.kind} {e.id}"
    return f"{what}: {metres5(d)} m {bearing(pos, e.pos)}"


def describe(obs: Observation) -> str:
    pos = obs.own.pos
    speed = math.hypot(obs.own.vel[0], obs.own.vel[1])
    lines = [f"you: north {metres5(pos[0])} east {metres5(pos[1])}, speed {round(speed)} m/s"]
    lines += [_entity_line(e, pos) for e in sorted(obs.entities, key=lambda e: (e.kind, e.id))]
    if not obs.entities:
        lines.append("nothing in sensing range")
    return "\n".join(lines)
