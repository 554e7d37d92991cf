"""One decision round of a UAV daemon (DESIGN §4): observe, list candidates, select,
gate, execute on the own body, talk, report. Anything invalid becomes a hold of this UAV.

It talks only to ports (Perception, Vehicle, PeerChannel, Selector) and the memory; the
round can therefore run against the Zenoh backends, the in-memory peer channel or anything
else that serves those ports.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from aeroweaver_edge.agent.candidates import CandidateSet, build_candidates
from aeroweaver_edge.agent.describe import describe
from aeroweaver_edge.agent.prompt import option_text
from aeroweaver_edge.agent.scoring import choose
from aeroweaver_edge.agent.state_text import state_text as make_state_text
from aeroweaver_edge.config import AgentConfig
from aeroweaver_edge.contracts.actions import HOLD, Intent, VehicleAction
from aeroweaver_edge.contracts.defaults import ALTITUDE_M, HOLD_SKILL
from aeroweaver_edge.contracts.hold_reasons import HoldCause, after_gate
from aeroweaver_edge.contracts.observation import MissionView, Observation
from aeroweaver_edge.contracts.ports import (
    DecisionRequest,
    PeerChannel,
    Perception,
    RoundTick,
    Selector,
    Vehicle,
)
from aeroweaver_edge.contracts.scores import Choice, LabelScores
from aeroweaver_edge.contracts.skill_api import SkillContext
from aeroweaver_edge.contracts.wire import MsgRef, Vec3
from aeroweaver_edge.safety.gate import GatedCommand, SafetyGate

if TYPE_CHECKING:
    from aeroweaver_edge.agent.history import InteractionHistory
    from aeroweaver_edge.agent.memory.async_memory import AsyncExperienceMemory
    from aeroweaver_edge.skills import SkillRegistry

log = logging.getLogger(__name__)

DEADLINE_MARGIN_S = 0.25  # leave the simulator / setpoint stream time to receive the command
ZERO: Vec3 = (0.0, 0.0, 0.0)
HOLD_TEXT = f"{HOLD_SKILL}()"


@dataclass(frozen=True, kw_only=True)
class RoundOutcome:
    episode: int
    round: int
    skill: str = HOLD_SKILL
    invocation: str = HOLD_TEXT
    label: str | None = None
    held: bool = True
    hold_reason: str | None = None
    reason: str = ""
    vel: Vec3 = ZERO
    state_text: str = ""
    corrected: bool = False
    sent: tuple[MsgRef, ...] = ()
    dropped: int = 0
    scores: LabelScores | None = None
    n_candidates: int = 0
    latency_s: float = 0.0
    cpu_s: float = 0.0  # this thread's CPU time over the round (in-process: other UAVs' too)
    violations: tuple[str, ...] = ()
    chosen_by_agent: bool = False  # False when an error, not the selector, produced the hold
    guess: str | None = None  # what a guessing skill recorded this round (the world scores it)
    hold_cause: HoldCause | None = None  # why it held (None: it did not)
    options: tuple[str, ...] = ()  # "A. skill(args)" per candidate, when it got that far
    advantages: Mapping[str, float] = field(default_factory=dict)  # label -> A (beta not applied)


@dataclass
class RoundContext:
    """Everything a round needs that outlives it."""

    uav: str
    uav_index: int
    registry: SkillRegistry
    selector: Selector
    gate: SafetyGate
    vehicle: Vehicle
    perception: Perception
    link: PeerChannel
    agent: AgentConfig
    memory: AsyncExperienceMemory | None = None
    history: InteractionHistory | None = None  # the agent's own past rounds, in its context
    altitude_m: float = ALTITUDE_M
    inbox_wait_s: float = 1.0
    memo: dict[str, str] = field(default_factory=dict)
    # flight: carries out a skill's vehicle action (take off, land, return) through the
    # daemon's flight phases; returns why it was refused, or None when done.
    act: Callable[[VehicleAction], Awaitable[str | None]] | None = None
    # operator approval: may this skill be offered? (None: every skill with options)
    offer: Callable[[str], bool] | None = None


async def _advantages(
    rc: RoundContext, view: MissionView, state_text: str, cs: CandidateSet
) -> dict[str, float]:
    if rc.memory is None or rc.agent.beta == 0:
        return {}
    by_skill: Mapping[str, float] = await rc.memory.advantages(
        view.task, view.role, state_text, {c.skill for c in cs.candidates}
    )
    return {c.label: by_skill.get(c.skill, 0.0) for c in cs.candidates}


def _execute(
    rc: RoundContext,
    skill: str,
    cs: CandidateSet,
    choice: Choice,
    obs: Observation,
    ctx: SkillContext,
) -> Intent | None:
    """The skill's intent, or ``None`` when its executor raised (the round holds)."""
    assert choice.label is not None
    try:
        return rc.registry.get(skill).execute(cs.params[choice.label], obs, ctx)
    except Exception:  # an executor bug must not take the UAV with it
        log.exception("%s: executor %s failed; holding", rc.uav, skill)
        return None


def _split_peers(task: str, obs: Observation) -> tuple[list[Vec3], list[Vec3]]:
    """(UAVs that run this gate too, bodies the world flies): the task's scripted roles
    run no gate of ours, so the safety gate must not count on them keeping their half of a
    gap. A task the registry does not know (a field mission): every peer is gated."""
    from aeroweaver_edge.tasks import TASK_NAMES, get_spec

    flown = set(get_spec(task).scripted_names) if task in TASK_NAMES else set()
    peers = obs.peers()
    return [e.pos for e in peers if e.role not in flown], [e.pos for e in peers if e.role in flown]


async def _apply(rc: RoundContext, gated: GatedCommand) -> None:
    if gated.held:
        await rc.vehicle.hold()
    else:
        await rc.vehicle.set_velocity(*gated.vel)


async def run_round(rc: RoundContext, tick: RoundTick, view: MissionView | None) -> RoundOutcome:
    """Run one round inside the tick's deadline; a missed deadline holds this UAV only."""
    started = time.monotonic()
    cpu = time.thread_time()
    budget = max(0.05, tick.deadline_s - DEADLINE_MARGIN_S)
    try:
        async with asyncio.timeout(budget):
            out = await _decide_and_act(rc, tick, view, started)
    except TimeoutError:
        await rc.vehicle.hold()
        out = RoundOutcome(
            episode=tick.episode,
            round=tick.round,
            hold_reason=f"missed the {budget:.1f} s round deadline",
            reason="deadline",
            latency_s=time.monotonic() - started,
            hold_cause="deadline",
        )
    return replace(out, cpu_s=time.thread_time() - cpu)


def _held(
    tick: RoundTick,
    why: str,
    cause: HoldCause,
    state_text: str,
    started: float,
    scores: LabelScores | None = None,
    n_candidates: int = 0,
    options: tuple[str, ...] = (),
    advantages: Mapping[str, float] | None = None,
) -> RoundOutcome:
    """A hold this UAV falls back to; not the selector's choice."""
    return RoundOutcome(
        episode=tick.episode,
        round=tick.round,
        hold_reason=why,
        reason=why,
        state_text=state_text,
        latency_s=time.monotonic() - started,
        scores=scores,
        n_candidates=n_candidates,
        hold_cause=cause,
        options=options,
        advantages=dict(advantages or {}),
    )


async def _decide_and_act(
    rc: RoundContext, tick: RoundTick, view: MissionView | None, started: float
) -> RoundOutcome:
    # 2. Observe, frozen for the round.
    percept = await rc.perception.sense(tick)
    own = percept.own
    rc.link.publish_beacon(
        round=tick.round,
        pos=own.pos,
        vel=own.vel,
        role=view.role if view else "",
        status="nominal" if view else "waiting",
    )
    messages = await rc.link.collect_inbox(
        expect=tick.expect, timeout_s=rc.inbox_wait_s, max_round=tick.round - 1
    )
    obs = Observation(
        uav=rc.uav,
        episode=tick.episode,
        round=tick.round,
        own=own,
        entities=tuple(percept.entities),
        messages=tuple(messages),
        memo=dict(rc.memo),
        facts=dict(percept.facts),
    )
    state_text = make_state_text(obs, view, context=rc.agent.state_context)
    if view is None:
        await rc.vehicle.hold()
        return _held(tick, "no mission assignment yet", "no_assignment", state_text, started)

    # 3. Candidates from the active subset.
    ctx = SkillContext(
        uav=rc.uav,
        uav_index=rc.uav_index,
        role=view.role,
        task=view.task,
        altitude_m=rc.altitude_m,
    )
    budget = rc.agent.max_labels
    if rc.selector.label_budget is not None:
        budget = min(budget, rc.selector.label_budget)
    cs = build_candidates(rc.registry, view.skills, obs, ctx, budget, allow=rc.offer)
    if cs.overflow:
        await rc.vehicle.hold()
        why = f"{cs.overflow} options beyond the label budget"
        return _held(tick, why, "no_candidates", state_text, started)
    if not cs.candidates:
        await rc.vehicle.hold()
        why = "no callable skill in the active subset"
        return _held(tick, why, "no_candidates", state_text, started)

    # 4. Select: base scores from the selector, corrected by experience.
    request = DecisionRequest(
        observation=obs,
        mission_text=view.text,
        role=view.role,
        local_goal=view.local_goal,
        constraints=view.constraints,
        skill_docs=[rc.registry.get(s).prompt_text() for s in view.skills if s in rc.registry],
        observation_text=describe(obs),
        candidates=cs.candidates,
        task=view.task,
        history=None if rc.history is None else rc.history.lines(tick.episode, tick.round),
    )
    scores = await rc.selector.score(request)
    advantages = await _advantages(rc, view, state_text, cs)
    choice = choose(scores, cs.labels, advantages, rc.agent.beta)
    options = tuple(f"{c.label}. {option_text(c)}" for c in cs.candidates)  # as prompted
    if choice.label is None:
        await rc.vehicle.hold()
        cause: HoldCause = "llm_failure" if scores.error is not None else "invalid_answer"
        return _held(
            tick,
            choice.reason,
            cause,
            state_text,
            started,
            scores=scores,
            n_candidates=len(cs.candidates),
            options=options,
            advantages=advantages,
        )
    cand = next(c for c in cs.candidates if c.label == choice.label)

    # 5. Gate and execute on this UAV's own vehicle only.
    executed = _execute(rc, cand.skill, cs, choice, obs, ctx)
    intent = HOLD if executed is None else executed
    neighbours, others = _split_peers(view.task, obs)
    gated = rc.gate.gate(intent.motion, own.pos, neighbours, others)
    await _apply(rc, gated)
    if intent.action is not None:  # flight: a vehicle action, after the phases' approval
        refused = await rc.act(intent.action) if rc.act else "vehicle actions are not wired"
        if refused is not None:
            gated = GatedCommand(gated.vel, True, (*gated.violations, refused))
    rc.memo.update(intent.memo)

    # 6. Talk: one send per message; "*" reaches every peer the routing rule lets it reach.
    # Without coordination reports (an ablation) only task-required messages go out.
    sent: list[MsgRef] = []
    dropped = 0
    for m in intent.messages:
        if m.purpose == "coordination" and not rc.agent.coordination_reports:
            continue
        ref = await rc.link.send(m.to, m.kind, dict(m.body), round=tick.round, purpose=m.purpose)
        if ref is None:
            dropped += 1
        else:
            sent.append(ref)
    return RoundOutcome(
        episode=tick.episode,
        round=tick.round,
        skill=cand.skill,
        invocation=cand.text,
        label=cand.label,
        held=gated.held,
        hold_reason="; ".join(gated.violations) if gated.held else None,
        reason=choice.reason,
        vel=gated.vel,
        state_text=state_text,
        corrected=choice.corrected,
        sent=tuple(sent),
        dropped=dropped,
        scores=scores,
        n_candidates=len(cs.candidates),
        latency_s=time.monotonic() - started,
        violations=gated.violations,
        chosen_by_agent=True,
        guess=intent.memo.get("guess"),
        hold_cause=after_gate(gated.held, executed is None, gated.violations),
        options=options,
        advantages=advantages,
    )
