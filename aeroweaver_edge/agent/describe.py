"""The textual observation, in two renderings of the same rounded numbers (metres to 5 m):

* ``describe`` -- what the LLM reads each round (the round part of the prompt, the
  baselines' prompts too). It is not cached, so it is terse: ``you -10,15`` (north, east;
  no speed: no option depends on it and it cost 2-3 tokens a round), then one line per
  kind of entity, ``landmark: L0 30 NE, L1 25 S`` (id, metres, compass point). The cached
  system message explains the format once (``prompt.FORMAT``): SmolLM2 spends a token per
  digit and per unit, and "landmark L0: 30 m NE" cost 10 tokens per entity where
  ``L0 30 NE`` costs 6.
* ``describe_state`` -- the base of the state text that experience retrieval matches on
  (``agent.state_text``), unchanged so stored experience keeps matching: one entity per
  line with the id right before the distance, so the retrieval tokeniser pairs them
  (``uav1~10``).
"""

from __future__ import annotations

import math
from typing import Any

from aeroweaver_edge.contracts.observation import Observation, horizontal_distance
from aeroweaver_edge.contracts.wire import Entity, Vec3

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


def pop_place(
    body: dict[str, Any], own: Vec3 | tuple[float, float], *, unit: str = " m"
) -> str | None:
    """``"<d> m <bearing>"`` from ``own`` to the body's (north, east), which it removes from
    ``body`` (``unit=""``: ``"<d> <bearing>"``, the prompt's form); ``None`` (body
    untouched) when that is not a place: not two numbers, not finite, or beyond
    ``MAX_PLACE_M``."""
    n, e = _coordinate(body.get("north")), _coordinate(body.get("east"))
    if n is None or e is None:
        return None
    del body["north"], body["east"]
    d = math.hypot(n - own[0], e - own[1])
    return f"{metres5(d)}{unit} {bearing(own, (n, e))}"


def _entity_line(e: Entity, pos: Vec3) -> str:
    d = horizontal_distance(pos, e.pos)
    if e.kind == "uav":  # the id says it is a UAV; the role says what it does
        what = f"{e.role or 'uav'} {e.id}"
    else:
        what = f"{e.kind} ({e.role}) {e.id}" if e.role else f"{e.kind} {e.id}"
    return f"{what}: {metres5(d)} m {bearing(pos, e.pos)}"


def describe_state(obs: Observation) -> str:
    """The observation as retrieval text (``agent.state_text``): one entity per line."""
    pos = obs.own.pos
    speed = math.hypot(obs.own.vel[0], obs.own.vel[1])
    lines = [f"you: north {metres5(pos[0])} east {metres5(pos[1])}, speed {round(speed)} m/s"]
    lines += [_entity_line(e, pos) for e in sorted(obs.entities, key=lambda e: (e.kind, e.id))]
    if not obs.entities:
        lines.append("nothing in sensing range")
    return "\n".join(lines)


def _group(e: Entity) -> str:
    if e.kind == "uav":  # the id says it is a UAV; the role says what it does
        return e.role or "uav"
    return f"{e.kind} ({e.role})" if e.role else e.kind


def place(src: Vec3, dst: Vec3) -> str:
    """``"<d> <bearing>"``: where ``dst`` is seen from ``src`` as the prompt reads it."""
    return f"{metres5(horizontal_distance(src, dst))} {bearing(src, dst)}"


def describe(obs: Observation) -> str:
    """The observation as the LLM reads it (format in the module docstring): entities grouped
    by kind (and role), in the order of ``describe_state``."""
    pos = obs.own.pos
    lines = [f"you {metres5(pos[0])},{metres5(pos[1])}"]  # no speed: no option depends on it
    groups: dict[str, list[str]] = {}
    for e in sorted(obs.entities, key=lambda e: (e.kind, e.id)):
        groups.setdefault(_group(e), []).append(f"{e.id} {place(pos, e.pos)}")
    lines += [f"{what}: {', '.join(items)}" for what, items in groups.items()]
    if not obs.entities:
        lines.append("nothing in range")
    return "\n".join(lines)
