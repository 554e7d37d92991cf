"""The baselines' central node: one mesh session (identity ``central``), never the Commander.

Each round every UAV's ``RemoteSelector`` puts a ``CentralAsk`` on its own key
(``aw/<swarm>/uav/<id>/ask``): its observation text, received messages and lettered
options. The node gathers a round's asks until every present participant has asked (the
Commander's context names the participants, liveliness says who is present) or
``gather_s`` has passed since the first one, runs its policy (``centralized`` or
``hmas2``) and answers each UAV on ``aw/<swarm>/central/answer/<id>``. Lockstep-compatible:
the world stays frozen while the UAVs wait; an answer later than a UAV's round deadline is
of no use, and a UAV whose answer does not come holds (its own deadline).

Every LLM call is recorded where it is spent (``CallRecord``), one ``CentralRound`` per round
goes to ``on_round`` (the trace) and the totals go into the run summary. Nothing a peer
sends is trusted: an ask or review is accepted only on the key of the UAV it names, sent by
that UAV, for a participant.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

from aeroweaver_edge.contracts.wire import (
    Assignment,
    CentralAnswer,
    CentralAsk,
    CentralReview,
    HeaderFactory,
    Keys,
    MissionContext,
    last_chunk,
)
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_lab.baselines.protocol import Mission

log = logging.getLogger(__name__)


def uav_order(uav: str) -> tuple[str, int]:
    """``uav2`` before ``uav10``."""
    head = uav.rstrip("0123456789")
    tail = uav[len(head) :]
    return head, int(tail) if tail else -1


@dataclass(frozen=True)
class Verdict:
    """The central node's final word for one UAV."""

    label: str | None  # None: this UAV holds
    error: str | None = None  # no LLM answer at all (the UAV counts an LLM failure)
    reason: str = ""


@dataclass
class CallRecord:
    """One central LLM call, as spent."""

    episode: int
    round: int
    stage: str  # "decide" (centralized), "plan" / "revise" (hmas2)
    prompt: int = 0
    cached: int = 0
    completion: int = 0
    requests: int = 0
    latency_s: float = 0.0
    error: str | None = None
    answer: str = ""  # the raw answer text (cut at 400 characters)
    invalid: dict[str, str] = field(default_factory=dict)  # uav -> why it holds


@dataclass
class CentralRound:
    """What the node did in one round (one line of the trace's ``central`` field)."""

    episode: int
    round: int
    asked: list[str]
    missing: list[str]  # present participants whose ask did not come in time
    calls: list[CallRecord] = field(default_factory=list)
    proposal: dict[str, str | None] = field(default_factory=dict)  # hmas2
    reviews: dict[str, dict[str, Any]] = field(default_factory=dict)  # hmas2
    final: dict[str, str | None] = field(default_factory=dict)
    gather_s: float = 0.0
    wall_s: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["gather_s"] = round(self.gather_s, 4)
        out["wall_s"] = round(self.wall_s, 4)
        for c in out["calls"]:
            c["latency_s"] = round(c["latency_s"], 4)
        return out


@dataclass(frozen=True)
class RoundAsks:
    episode: int
    round: int
    asks: list[CentralAsk]  # in UAV order

    @property
    def uavs(self) -> list[str]:
        return [a.uav for a in self.asks]


class CentralIO(Protocol):
    """What a policy may do besides calling its LLM: propose to UAVs and hear reviews."""

    def propose(self, rnd: RoundAsks, labels: Mapping[str, str | None]) -> None: ...

    async def reviews(self, rnd: RoundAsks, timeout_s: float) -> dict[str, CentralReview]: ...


class CentralPolicy(Protocol):
    name: str

    async def decide(
        self, rnd: RoundAsks, mission: Mission, io: CentralIO, record: CentralRound
    ) -> dict[str, Verdict]: ...

    async def aclose(self) -> None: ...


SkillDocs = Callable[[list[str]], list[str]]
"""Skill names -> their prompt documents (the registry's ``prompt_text``)."""


class CentralNode:
    """Gathers asks per round, runs ``policy``, answers every UAV that asked."""

    def __init__(
        self,
        mesh: Mesh,
        swarm: str,
        policy: CentralPolicy,
        skill_docs: SkillDocs,
        *,
        gather_s: float = 3.0,
        on_round: Callable[[CentralRound], None] | None = None,
        headers: HeaderFactory | None = None,
    ) -> None:
        self.mesh = mesh
        self.keys = Keys(swarm)
        self.policy = policy
        self.skill_docs = skill_docs
        self.gather_s = gather_s
        self.on_round = on_round
        self.headers = headers or HeaderFactory("central")
        self.rounds: list[CentralRound] = []
        self.rejected = 0  # asks/reviews refused (wrong key, sender or not a participant)
        self._context: MissionContext | None = None
        self._assignments: dict[str, Assignment] = {}
        self._alive: set[str] = set()
        self._asks: dict[tuple[int, int], dict[str, CentralAsk]] = {}
        self._first_ask: dict[tuple[int, int], float] = {}
        self._reviews: dict[tuple[int, int], dict[str, CentralReview]] = {}
        self._changed = asyncio.Event()
        self._review_in = asyncio.Event()
        self._tasks: list[asyncio.Task[Any]] = []

    # ------------------------------------------------------------------ lifecycle

    async def start(self) -> None:
        asks = self.mesh.subscribe(self.keys.ask("*"), CentralAsk)
        reviews = self.mesh.subscribe(self.keys.review("*"), CentralReview)
        context = self.mesh.subscribe(self.keys.context, MissionContext)
        assign = self.mesh.subscribe(self.keys.assign("*"), Assignment)
        alive = self.mesh.watch_liveliness(self.keys.alive_uav("*"))
        self._tasks = [
            asyncio.create_task(self._pump(asks, self._on_ask), name="central-asks"),
            asyncio.create_task(self._pump(reviews, self._on_review), name="central-reviews"),
            asyncio.create_task(self._pump(context, self._on_context), name="central-context"),
            asyncio.create_task(self._pump(assign, self._on_assign), name="central-assign"),
            asyncio.create_task(self._pump_alive(alive), name="central-alive"),
            asyncio.create_task(self._serve(), name="central-serve"),
        ]
        self.mesh.declare_token(self.keys.alive_central)
        for _key, ctx in await self.mesh.get(self.keys.context, MissionContext, timeout_s=1.0):
            self._on_context("", ctx)

    async def aclose(self) -> None:
        await cancel_all(self._tasks)
        await self.policy.aclose()

    async def _pump(self, sub: Any, handle: Callable[[str, Any], None]) -> None:
        async for key, msg in sub:
            handle(key, msg)

    async def _pump_alive(self, watch: Any) -> None:
        async for key, alive in watch:
            uav = last_chunk(key)
            if alive:
                self._alive.add(uav)
            else:
                self._alive.discard(uav)
            self._changed.set()

    # ------------------------------------------------------------------ intake

    @property
    def participants(self) -> list[str]:
        return list(self._context.participants) if self._context is not None else []

    def _on_context(self, _key: str, ctx: MissionContext) -> None:
        if ctx.h.sender != "cmdr":
            self.rejected += 1
            return
        self._context = ctx

    def _on_assign(self, key: str, a: Assignment) -> None:
        if a.h.sender != "cmdr" or last_chunk(key) != a.uav:
            self.rejected += 1
            return
        self._assignments[a.uav] = a

    def _genuine(self, key: str, uav: str, sender: str) -> bool:
        ok = self.keys.uav_of(key) == uav == sender
        if ok and self._context is not None:
            ok = uav in self._context.participants
        if not ok:
            self.rejected += 1
        return ok

    def _on_ask(self, key: str, ask: CentralAsk) -> None:
        if not self._genuine(key, ask.uav, ask.h.sender):
            return
        where = (ask.episode, ask.round)
        self._asks.setdefault(where, {})[ask.uav] = ask
        self._first_ask.setdefault(where, time.monotonic())
        self._changed.set()

    def _on_review(self, key: str, review: CentralReview) -> None:
        if not self._genuine(key, review.uav, review.h.sender):
            return
        self._reviews.setdefault((review.episode, review.round), {})[review.uav] = review
        self._review_in.set()

    def mission(self) -> Mission:
        ctx = self._context
        names = sorted({s for a in self._assignments.values() for s in a.skills})
        return Mission(
            text=ctx.text if ctx else "",
            constraints=list(ctx.constraints) if ctx else [],
            skill_docs=self.skill_docs(names),
        )

    # ------------------------------------------------------------------ rounds

    def _expected(self) -> set[str]:
        return set(self.participants) & self._alive

    async def _serve(self) -> None:
        """One round at a time, always the newest: a round that a newer one overtook while
        it was gathering is dropped (its UAVs have held on their own deadline)."""
        while True:
            await self._changed.wait()
            self._changed.clear()
            if not self._asks:
                continue
            where = max(self._asks)
            for old in [k for k in self._asks if k < where]:
                self._asks.pop(old, None)
                self._first_ask.pop(old, None)
            deadline = self._first_ask[where] + self.gather_s
            while not self._expected() <= set(self._asks[where]):
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                self._changed.clear()
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(remaining):
                        await self._changed.wait()
                if max(self._asks) != where:
                    break
            if max(self._asks) != where:
                self._changed.set()  # serve the newer round next
                continue
            asks = self._asks.pop(where)
            gathered = time.monotonic() - self._first_ask.pop(where)
            await self._decide(where, asks, gathered)
            self._reviews.pop(where, None)

    async def _decide(
        self, where: tuple[int, int], asks: dict[str, CentralAsk], gathered: float
    ) -> None:
        started = time.monotonic()
        rnd = RoundAsks(where[0], where[1], [asks[u] for u in sorted(asks, key=uav_order)])
        missing = sorted(self._expected() - set(asks), key=uav_order)
        record = CentralRound(where[0], where[1], rnd.uavs, missing, gather_s=gathered)
        try:
            verdicts = await self.policy.decide(rnd, self.mission(), self, record)
        except Exception as exc:  # a policy bug holds this round's UAVs, never the node
            log.exception("central policy %s failed", self.policy.name)
            verdicts = {
                u: Verdict(None, f"central policy failed: {type(exc).__name__}") for u in asks
            }
        for uav in rnd.uavs:
            v = verdicts.get(uav, Verdict(None, "no verdict"))
            record.final[uav] = v.label
            self._answer(uav, where, "final", v)
        record.wall_s = time.monotonic() - started
        self.rounds.append(record)
        if self.on_round is not None:
            self.on_round(record)

    def _answer(self, uav: str, where: tuple[int, int], phase: str, v: Verdict) -> None:
        self.mesh.put(
            self.keys.central_answer(uav),
            CentralAnswer(
                h=self.headers.next(),
                uav=uav,
                episode=where[0],
                round=where[1],
                phase="final" if phase == "final" else "proposal",
                label=v.label,
                error=v.error,
                reason=v.reason[:200],
            ),
            block=True,
        )

    # ------------------------------------------------------------------ CentralIO

    def propose(self, rnd: RoundAsks, labels: Mapping[str, str | None]) -> None:
        for uav in rnd.uavs:
            label = labels.get(uav)
            self._answer(uav, (rnd.episode, rnd.round), "proposal", Verdict(label, None, "plan"))

    async def reviews(self, rnd: RoundAsks, timeout_s: float) -> dict[str, CentralReview]:
        """The reviews of ``rnd``'s UAVs, waiting until all came or ``timeout_s`` passed."""
        where = (rnd.episode, rnd.round)
        want = set(rnd.uavs)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                while not want <= set(self._reviews.get(where, {})):
                    self._review_in.clear()
                    await self._review_in.wait()
        got = self._reviews.get(where, {})
        return {u: got[u] for u in rnd.uavs if u in got}

    # ------------------------------------------------------------------ totals

    def totals(self) -> dict[str, Any]:
        """Tokens and calls the central node spent, in all and per episode."""
        calls = [c for r in self.rounds for c in r.calls]
        by_episode: dict[int, dict[str, int]] = {}
        for c in calls:
            e = by_episode.setdefault(c.episode, {"tokens": 0, "llm_calls": 0})
            e["tokens"] += c.prompt + c.completion
            e["llm_calls"] += c.requests
        prompt = sum(c.prompt for c in calls)
        completion = sum(c.completion for c in calls)
        return {
            "policy": self.policy.name,
            "rounds": len(self.rounds),
            "llm_calls": sum(c.requests for c in calls),
            "call_errors": sum(c.error is not None for c in calls),
            "invalid": sum(len(c.invalid) for c in calls if c.stage != "plan"),
            "tokens": {
                "prompt": prompt,
                "prompt_cached": sum(c.cached for c in calls),
                "completion": completion,
                "total": prompt + completion,
            },
            "by_episode": {str(k): v for k, v in sorted(by_episode.items())},
            "missing_asks": sum(len(r.missing) for r in self.rounds),
            "rejected": self.rejected,
        }


__all__ = [
    "CallRecord",
    "CentralIO",
    "CentralNode",
    "CentralPolicy",
    "CentralRound",
    "RoundAsks",
    "Verdict",
    "uav_order",
]
