"""Helpers the nine scripted reference policies share.

A reference policy is a heuristic, not a model: its returns are a sanity bound for the
benchmark and a deterministic oracle for tests, never evidence about an LLM. Each task's
policy (``reference`` on its definition) maps every labelled candidate to a utility; the
rules common to all of them live here so they are written once:

* an unknown skill scores ``UNKNOWN`` (-4), ``hold_position`` ``HOLD`` (-3);
* ``return_in_bounds`` wins (+8) when the UAV is beyond mpe2's 63 m penalty line, else -2;
* ``explore_local`` is the fallback (+1) when nothing the policy wants is available, else -1.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Final

from aeroweaver_edge.contracts.defaults import ARENA_HALF_M, HOLD_SKILL
from aeroweaver_edge.contracts.observation import Observation, horizontal_distance
from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest
from aeroweaver_edge.contracts.wire import Entity, Vec3

UNKNOWN: Final = -4.0
HOLD: Final = -3.0
BOUNDARY_M: Final = ARENA_HALF_M * 0.9  # 63 m: where mpe2's boundary penalty starts


def out_of_bounds(obs: Observation) -> bool:
    pos = obs.own.pos
    return max(abs(pos[0]), abs(pos[1])) > BOUNDARY_M


def common(c: Candidate, obs: Observation, *, wants_something: bool) -> float | None:
    """The shared rules above; ``None`` for a skill the task policy must score itself."""
    if c.skill == HOLD_SKILL:
        return HOLD
    if c.skill == "return_in_bounds":
        return 8.0 if out_of_bounds(obs) else -2.0
    if c.skill == "explore_local":
        return -1.0 if wants_something else 1.0
    return None


def target(obs: Observation, c: Candidate) -> Entity | None:
    """The visible entity a candidate's ``target_id`` names, if any."""
    tid = c.params.get("target_id")
    return obs.entity(tid) if isinstance(tid, str) else None


def distance_to(obs: Observation, pos: Vec3) -> float:
    return horizontal_distance(obs.own.pos, pos)


def known_positions(
    obs: Observation, roles: Iterable[str] | None = None, kinds: Iterable[str] = ("intent",)
) -> dict[str, Vec3]:
    """This UAV and every teammate it knows of: visible peers (with a role in ``roles``, if
    given) and the senders of ``kinds`` messages, at the position the message carried."""
    wanted = None if roles is None else set(roles)
    kinds = set(kinds)
    out: dict[str, Vec3] = {obs.uav: obs.own.pos}
    for peer in obs.peers():
        if wanted is None or peer.role in wanted:
            out[peer.id] = peer.pos
    for msg in obs.messages:
        if msg.kind in kinds and msg.sender_pos is not None and msg.h.sender not in out:
            out[msg.h.sender] = msg.sender_pos
    return out


def greedy_assignment(agents: dict[str, Vec3], targets: dict[str, Vec3]) -> dict[str, str]:
    """Target id -> agent id, closest pairs first (ties by ids): each agent and target once."""
    pairs = sorted(
        (horizontal_distance(ap, tp), aid, tid)
        for aid, ap in agents.items()
        for tid, tp in targets.items()
    )
    taken: set[str] = set()
    out: dict[str, str] = {}
    for _, aid, tid in pairs:
        if aid not in taken and tid not in out:
            out[tid] = aid
            taken.add(aid)
    return out


def score_all(
    request: DecisionRequest,
    rule: Callable[[Candidate], float | None],
    *,
    wants_something: bool,
) -> dict[str, float]:
    """Utilities for every candidate: the task's ``rule`` first, the common rules next."""
    obs = request.observation
    out: dict[str, float] = {}
    for c in request.candidates:
        value = rule(c)
        if value is None:
            value = common(c, obs, wants_something=wants_something)
        out[c.label] = UNKNOWN if value is None or not math.isfinite(value) else value
    return out


__all__ = [
    "BOUNDARY_M",
    "HOLD",
    "UNKNOWN",
    "common",
    "distance_to",
    "greedy_assignment",
    "known_positions",
    "out_of_bounds",
    "score_all",
    "target",
]
