"""A deterministic scorer with the LLM selector's interface, for tests and baselines.

It is a heuristic, not a model: results from it say nothing about LLM quality. It scores
the labelled candidates with a greedy nearest-uncovered-landmark assignment among the UAVs
this one can see (and the intents peers announced), then returns log-softmax scores so the
same ``choose`` arithmetic (and experience correction) applies as for an LLM.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from aeroweaver_edge.agent.scoring import LabelScores
from aeroweaver_edge.observation import Observation, horizontal_distance
from aeroweaver_edge.ports import Candidate, DecisionRequest
from aeroweaver_edge.wire import Vec3

BOUNDARY_M = 63.0  # where mpe2's boundary penalty starts at 70 m per unit


def _greedy_assignment(obs: Observation) -> dict[str, str]:
    """Landmark id -> UAV id, closest pairs first (ties by ids), over known UAVs."""
    uavs: dict[str, Vec3] = {obs.uav: obs.own.pos}
    for peer in obs.peers():
        uavs[peer.id] = peer.pos
    for msg in obs.messages:
        if msg.kind == "intent" and msg.sender_pos is not None and msg.h.sender not in uavs:
            uavs[msg.h.sender] = msg.sender_pos
    landmarks = {e.id: e.pos for e in obs.of_kind("landmark")}
    pairs = sorted(
        (horizontal_distance(up, lp), uid, lid)
        for uid, up in uavs.items()
        for lid, lp in landmarks.items()
    )
    taken_u: set[str] = set()
    out: dict[str, str] = {}
    for _, uid, lid in pairs:
        if uid not in taken_u and lid not in out:
            out[lid] = uid
            taken_u.add(uid)
    return out


def _utility(c: Candidate, obs: Observation, owner: Mapping[str, str]) -> float:
    pos = obs.own.pos
    out_of_bounds = max(abs(pos[0]), abs(pos[1])) > BOUNDARY_M
    if c.skill == "cover_landmark":
        target = obs.entity(str(c.params.get("target_id")))
        if target is None:
            return -5.0
        d = horizontal_distance(pos, target.pos) / 100.0
        holder = owner.get(target.id)
        if holder == obs.uav:
            return 10.0 - d
        return (5.0 if holder is None else 0.0) - d
    if c.skill == "return_in_bounds":
        return 8.0 if out_of_bounds else -2.0
    if c.skill == "explore_local":
        return -1.0 if obs.of_kind("landmark") else 1.0
    if c.skill == "hold_position":
        return -3.0
    return -4.0  # a skill this scorer does not understand


class NearestUncoveredScorer:
    name = "scripted:nearest-uncovered"

    def __init__(self, temperature: float = 1.0) -> None:
        self.temperature = temperature

    @property
    def label_budget(self) -> int | None:
        return None

    async def score(self, request: DecisionRequest) -> LabelScores:
        obs = request.observation
        owner = _greedy_assignment(obs)
        utils = {c.label: _utility(c, obs, owner) / self.temperature for c in request.candidates}
        if not utils:
            return LabelScores(logprobs={})
        top = max(utils.values())
        log_z = top + math.log(sum(math.exp(u - top) for u in utils.values()))
        return LabelScores(logprobs={lb: u - log_z for lb, u in utils.items()})

    async def aclose(self) -> None:
        return None
