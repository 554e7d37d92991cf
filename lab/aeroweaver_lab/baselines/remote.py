"""The UAV side of a baseline: a ``Selector`` that asks the central node.

``score`` puts this round's ``CentralAsk`` (observation text, received messages, lettered
options) on the UAV's own key and waits for the central node's final answer for this
(episode, round). With HMAS-2 it first gets a proposal, reviews it with one local LLM call
(its own client, its own cache slot) and puts its ``CentralReview``; when the central plan
call failed there is no proposal, only the final answer carrying the error, which ends the
wait at once (an ``llm_failure`` hold now, not a ``deadline`` hold a round later). The
final letter comes back as a text label (no logprobs, so the experience correction is off,
as the baselines have no reward memory); a missing or invalid letter is an invalid answer
and the UAV holds, a central call that failed is an LLM failure. The round's deadline bounds
the wait (the round is cancelled and the UAV holds).

Tokens of the local review are reported with the round they were spent in; if the round's
deadline cut the wait after the review, they go out with the next round instead, so totals
still add up.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from aeroweaver_edge.agent.prompt import PromptLimits, format_message, option_text
from aeroweaver_edge.contracts.ports import DecisionRequest
from aeroweaver_edge.contracts.scores import LabelScores
from aeroweaver_edge.contracts.wire import (
    CentralAnswer,
    CentralAsk,
    CentralReview,
    HeaderFactory,
    Keys,
)
from aeroweaver_edge.mesh.session import Mesh, Subscription
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_lab.baselines.hmas2 import local_review
from aeroweaver_lab.baselines.json_chat import JsonMode

log = logging.getLogger(__name__)

KEEP_ROUNDS = 4  # answers kept per UAV (older ones are of no use)


class RemoteSelector:
    """``Selector`` whose choice comes from the baseline's central node."""

    def __init__(
        self,
        mesh: Mesh,
        swarm: str,
        uav: str,
        headers: HeaderFactory,
        *,
        mode: str,
        review_client: Any = None,  # ChatClient for HMAS-2's local review
        review_slot: int | None = None,
        mission_id: str = "",
    ) -> None:
        if mode not in ("centralized", "hmas2"):
            raise ValueError(f"unknown baseline {mode!r}")
        if mode == "hmas2" and review_client is None:
            raise ValueError("hmas2 needs a local LLM client for the review")
        self.mesh = mesh
        self.keys = Keys(swarm)
        self.uav = uav
        self.headers = headers
        self.mode = mode
        self.name = f"central:{mode}"
        self.client = review_client
        self.review_slot = review_slot
        self.mission_id = mission_id
        self._json = JsonMode()
        self._answers: dict[tuple[int, int, str], CentralAnswer] = {}
        self._arrived = asyncio.Condition()
        self._tasks: list[asyncio.Task[None]] = []
        self._carry = (0, 0, 0)  # review tokens (prompt, cached, completion) not yet reported
        self.rejected = 0

    @property
    def label_budget(self) -> int | None:
        return None

    @property
    def requests_sent(self) -> int:
        """Local LLM requests (HMAS-2 reviews); the central node's are counted there."""
        return int(self.client.requests_sent) if self.client is not None else 0

    async def start(self) -> None:
        sub = self.mesh.subscribe(self.keys.central_answer(self.uav), CentralAnswer)
        self._tasks.append(asyncio.create_task(self._pump(sub), name=f"{self.uav}-central"))

    async def aclose(self) -> None:
        await cancel_all(self._tasks)
        if self.client is not None:
            await self.client.aclose()

    async def _pump(self, sub: Subscription[CentralAnswer]) -> None:
        async for _key, ans in sub:
            if ans.uav != self.uav or ans.h.sender != "central":
                self.rejected += 1
                continue
            async with self._arrived:
                self._answers[(ans.episode, ans.round, ans.phase)] = ans
                newest = max((e, r) for e, r, _ in self._answers)
                for k in [k for k in self._answers if k[:2] < (newest[0], newest[1] - KEEP_ROUNDS)]:
                    del self._answers[k]
                self._arrived.notify_all()

    async def _wait(self, episode: int, rnd: int, *phases: str) -> CentralAnswer:
        """The first of ``phases`` (in that order of preference) to arrive for the round."""
        keys = [(episode, rnd, phase) for phase in phases]
        async with self._arrived:
            await self._arrived.wait_for(lambda: any(k in self._answers for k in keys))
            return self._answers.pop(next(k for k in keys if k in self._answers))

    def _ask(self, request: DecisionRequest) -> CentralAsk:
        obs = request.observation
        limits = PromptLimits()
        messages = list(obs.messages)[-limits.max_messages :]
        own = (obs.own.pos[0], obs.own.pos[1])
        return CentralAsk(
            h=self.headers.next(),
            uav=self.uav,
            mission_id=self.mission_id,
            episode=obs.episode,
            round=obs.round,
            role=request.role,
            local_goal=request.local_goal,
            observation=request.observation_text,
            messages=[format_message(m, limits, own, obs.round) for m in messages],
            options=[f"{c.label}. {option_text(c)}" for c in request.candidates],
        )

    async def _review(self, request: DecisionRequest, proposed: str | None) -> tuple[int, int, int]:
        """HMAS-2's local review of the proposal, put on the UAV's key; its tokens."""
        obs = request.observation
        review, ans = await local_review(
            self.client, self._json, request, proposed, agent=self.uav, slot=self.review_slot
        )
        self.mesh.put(
            self.keys.review(self.uav),
            CentralReview(
                h=self.headers.next(), uav=self.uav, episode=obs.episode, round=obs.round,
                agree=review.agree, suggest=review.choice, error=ans.error,
            ),
            block=True,
        )  # fmt: skip
        return ans.prompt_tokens, ans.cached_tokens, ans.completion_tokens

    async def score(self, request: DecisionRequest) -> LabelScores:
        if not request.candidates:
            return LabelScores(logprobs={}, error="no candidates to choose from")
        obs = request.observation
        self.mesh.put(self.keys.ask(self.uav), self._ask(request), block=True)
        spent = (0, 0, 0)
        try:
            final: CentralAnswer | None = None
            if self.mode == "hmas2":
                first = await self._wait(obs.episode, obs.round, "final", "proposal")
                if first.phase == "final":  # the plan call failed: no proposal is coming
                    final = first
                else:
                    spent = await self._review(request, first.label)
            if final is None:
                final = await self._wait(obs.episode, obs.round, "final")
        except asyncio.CancelledError:
            self._carry = tuple(a + b for a, b in zip(self._carry, spent, strict=True))  # type: ignore[assignment]
            raise
        prompt, cached, completion = (a + b for a, b in zip(self._carry, spent, strict=True))
        self._carry = (0, 0, 0)
        return LabelScores(
            logprobs={},
            text_label=final.label,
            logprobs_usable=False,
            prompt_tokens=prompt,
            cached_tokens=cached,
            completion_tokens=completion,
            error=final.error,
            extra={"probe": self.name, "central": final.reason},
        )


__all__ = ["RemoteSelector"]
