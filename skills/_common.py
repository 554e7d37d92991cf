"""Helpers shared by the task-skill executors (not a skill: the loader skips ``_`` folders
and files, and this is a plain module of the ``skills`` package).

Conventions every executor here follows (the simulator tasks build observations to match):

* Every flying agent is an entity of kind ``"uav"``; its ``role`` says what it is
  (``pursuer``, ``evader``, ``leader``, ``forager``, ``collector``, ``deposit_red``, ...).
* Static objects: ``landmark``, ``food``, ``forest``, ``treasure`` (``role`` = colour, e.g.
  ``"red"``), ``slot`` (a formation slot), ``waypoint`` (a mission point of interest).
* Private per-UAV facts arrive in ``obs.facts`` (from the Perception port, fresh every
  round, only what the UAV's role may know) as strings: ``goal_landmark``,
  ``private_symbol``, ``key``, ``slot``, ``cargo``. ``obs.memo`` is the UAV's own record
  across rounds: a skill that guesses puts ``guess`` in its intent's memo, and the daemon
  sends that guess to the world in its command (the world scores it).
* Message bodies are untrusted data: every field is type-checked before use.
"""

from __future__ import annotations

import math
from collections.abc import Collection

from aeroweaver_edge.contracts.actions import Intent, MoveTo, Outgoing
from aeroweaver_edge.contracts.observation import Observation
from aeroweaver_edge.contracts.skill_api import SkillContext
from aeroweaver_edge.contracts.wire import Entity, InboxMessage

MAX_TARGETS = 8
"""Options a target skill offers at most: the nearest visible targets (``ctx.settings``
``max_targets`` overrides). Keeps a crowded view (50 landmarks) inside the 26-label budget;
with few targets every one is offered, in the order they were observed."""
SYMBOLS = range(4)  # private-communication symbols 0..3 (one-hot over dim_c = 4 in mpe2)
_SYMBOL_TEXT = frozenset(str(s) for s in SYMBOLS)
Scalar = str | int | float | bool
MAX_ID = 64  # SkillParams' str_max_length: a longer id can never be a parameter


def usable_id(value: object) -> bool:
    """A string that can be a ``target_id`` parameter (untrusted ids are checked first)."""
    return isinstance(value, str) and 0 < len(value) <= MAX_ID


def allowed(ctx: SkillContext, roles: Collection[str]) -> bool:
    """The role precondition: a skill activated for another role is never callable."""
    return ctx.role in roles


def visible(
    obs: Observation, target_id: str, kind: str, roles: Collection[str] | None = None
) -> Entity | None:
    """The entity ``target_id`` if it is visible now, of ``kind`` (and one of ``roles``)."""
    e = obs.entity(target_id)
    if e is None or e.kind != kind or (roles is not None and e.role not in roles):
        return None
    return e


def of_kind(obs: Observation, kind: str, roles: Collection[str] | None = None) -> list[Entity]:
    """Visible entities of ``kind`` (and, if given, with a ``role`` in ``roles``) whose id
    can be a parameter."""
    return [e for e in obs.of_kind(kind) if usable_id(e.id) and (roles is None or e.role in roles)]


def nearest_first_k(obs: Observation, entities: list[Entity], ctx: SkillContext) -> list[Entity]:
    """The ``max_targets`` entities nearest this UAV (ties: id), kept in observation order."""
    k = int(ctx.settings.get("max_targets", MAX_TARGETS))
    if len(entities) <= k:
        return entities
    pos = obs.own.pos

    def dist(e: Entity) -> tuple[float, str]:
        return (math.hypot(e.pos[0] - pos[0], e.pos[1] - pos[1]), e.id)

    keep = {e.id for e in sorted(entities, key=dist)[:k]}
    return [e for e in entities if e.id in keep]


def metres(x: float) -> float:
    """A coordinate or speed as a message carries it: 0.1 m (m/s) is finer than any sensor
    here, and 15-digit floats cost ~18 prompt tokens each on small-vocabulary models."""
    return round(float(x), 1)


def move_and_announce(
    skill: str,
    target_id: str,
    north: float,
    east: float,
    ctx: SkillContext,
    **extra: Scalar,
) -> Intent:
    """Fly to (north, east) at the UAV's fixed altitude and send an ``intent`` message
    ``{skill, target_id, north, east, **extra}`` to every reachable peer (position to 0.1 m)."""
    body: dict[str, Scalar] = {
        "skill": skill,
        "target_id": target_id,
        "north": metres(north),
        "east": metres(east),
    }
    body.update(extra)
    announce = Outgoing(to="*", kind="intent", body=body)
    return Intent(MoveTo((north, east, -ctx.altitude_m)), messages=(announce,))


def number(value: object) -> float | None:
    """A finite number from an untrusted message field (bools are not numbers)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    x = float(value)
    return x if math.isfinite(x) else None


def point(body: dict[str, Scalar]) -> tuple[float, float] | None:
    """The ``north``/``east`` position carried by a message body, if well formed."""
    north, east = number(body.get("north")), number(body.get("east"))
    return None if north is None or east is None else (north, east)


def newest_first(obs: Observation, kind: str) -> list[InboxMessage]:
    """Received messages of ``kind``, newest round first (ties: sender, then sequence)."""
    msgs = [m for m in obs.messages if m.kind == kind]
    return sorted(msgs, key=lambda m: (-m.round, m.h.sender, -m.h.seq))


def latest_by_target(obs: Observation, kind: str) -> dict[str, InboxMessage]:
    """The newest message of ``kind`` per ``target_id`` named in its body, in first-seen
    order (newest first). Messages without a string ``target_id`` are ignored."""
    out: dict[str, InboxMessage] = {}
    for m in newest_first(obs, kind):
        target = m.body.get("target_id")
        if isinstance(target, str) and usable_id(target) and target not in out:
            out[target] = m
    return out


def symbol(value: object) -> int | None:
    """A private-communication symbol 0..3 from a fact or memo string ("0".."3")."""
    return int(value) if isinstance(value, str) and value in _SYMBOL_TEXT else None


def wire_symbol(value: object) -> int | None:
    """A symbol 0..3 from a message field: an integer, never a bool, float or string."""
    ok = isinstance(value, int) and not isinstance(value, bool) and value in SYMBOLS
    return value if ok and isinstance(value, int) else None


def ciphertexts(obs: Observation) -> list[int]:
    """Distinct well-formed ciphertext symbols received, newest first."""
    out: list[int] = []
    for m in newest_first(obs, "ciphertext"):
        c = wire_symbol(m.body.get("ciphertext"))
        if c is not None and c not in out:
            out.append(c)
    return out


def target_report(skill: str, target: Entity) -> Outgoing:
    """The ``target`` message pursuers and the leader send: where a target is and how it
    moves, so peers that cannot see it can follow (``follow_peer``)."""
    return Outgoing(
        to="*",
        kind="target",
        body={
            "skill": skill,
            "target_id": target.id,
            "north": metres(target.pos[0]),
            "east": metres(target.pos[1]),
            "vn": metres(target.vel[0]),
            "ve": metres(target.vel[1]),
        },
    )
