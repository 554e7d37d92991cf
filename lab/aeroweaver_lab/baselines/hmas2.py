"""HMAS-2 baseline (Chen et al. 2024, adapted as the paper says): a central plan, one local
review per UAV from its own observation, at most one central revision, then execution.

Central side (``Hmas2Policy``): the plan is the centralized call; each UAV gets its
proposed letter (``CentralAnswer`` phase ``proposal``); the node waits (bounded) for the
UAVs' ``CentralReview``s. As in the authors' protocol, the plan is executed as it stands
when no review disagrees (every local agent agreed, or sent no usable review: silence is not
feedback), and only a disagreement buys the revision call, which continues the plan
conversation (same cached prefix) with the reviews and asks for the final plan once (the
AeroWeaver paper's "revises the plan once": the authors iterate until consensus, we cap it
at one round so a round's deadline stays bounded). If the revision call fails, the plan
stands; a letter that is invalid in the final answer makes that UAV hold.

UAV side (``local_review``): one local LLM call in the daemon from the UAV's own prompt
(mission, role, its skill documents, observation, messages, options) plus the proposal,
answered as ``{"agree": bool, "choice": letter}``.
"""

from __future__ import annotations

from aeroweaver_edge.agent.prompt import agent_part, option_text, round_part, static_part
from aeroweaver_edge.contracts.ports import DecisionRequest
from aeroweaver_edge.llm.client import CallTag, ChatClient
from aeroweaver_lab.baselines.central import CentralIO, CentralRound, RoundAsks, Verdict
from aeroweaver_lab.baselines.centralized import plan_call
from aeroweaver_lab.baselines.json_chat import JsonAnswer, JsonMode, json_chat
from aeroweaver_lab.baselines.protocol import (
    REVIEW_MAX_TOKENS,
    REVIEW_SYSTEM,
    Mission,
    Review,
    check_review,
    review_schema,
    review_user_tail,
    revision_messages,
)


class Hmas2Policy:
    name = "hmas2"

    def __init__(
        self, client: ChatClient, *, slot: int | None = None, review_wait_s: float = 60.0
    ) -> None:
        self.client = client
        self.slot = slot
        self.review_wait_s = review_wait_s
        self.mode = JsonMode()

    async def decide(
        self, rnd: RoundAsks, mission: Mission, io: CentralIO, record: CentralRound
    ) -> dict[str, Verdict]:
        proposal, plan_rec, plan_msgs = await plan_call(
            self.client, self.mode, rnd, mission, "plan", self.slot
        )
        record.calls.append(plan_rec)
        record.proposal = dict(proposal)
        if plan_rec.error is not None:
            return {u: Verdict(None, plan_rec.error, "central plan failed") for u in rnd.uavs}
        io.propose(rnd, proposal)
        got = await io.reviews(rnd, self.review_wait_s)
        reviews = {u: Review(r.agree, r.suggest) for u, r in got.items()}
        record.reviews = {
            u: {"agree": r.agree, "suggest": r.suggest, "error": r.error} for u, r in got.items()
        }
        if not any(r.agree is False for r in reviews.values()):
            why = plan_rec.invalid
            return {
                u: Verdict(proposal[u], None, "plan agreed" if proposal[u] else why.get(u, ""))
                for u in rnd.uavs
            }
        msgs = revision_messages(plan_msgs, plan_rec.answer, rnd.asks, proposal, reviews)
        final, rev_rec, _ = await plan_call(
            self.client, self.mode, rnd, mission, "revise", self.slot, messages=msgs
        )
        record.calls.append(rev_rec)
        if rev_rec.error is not None:  # the plan stands
            return {u: Verdict(proposal[u], None, "revision failed; plan kept") for u in rnd.uavs}
        return {
            u: Verdict(final[u], None, "revised plan" if final[u] else rev_rec.invalid.get(u, ""))
            for u in rnd.uavs
        }

    async def aclose(self) -> None:
        await self.client.aclose()


def review_messages(request: DecisionRequest, proposed: str | None) -> list[dict[str, str]]:
    """The UAV's own prompt (as its LLM selector would build it), reviewing the proposal."""
    body = agent_part(request) + round_part(request).rsplit("\nAnswer (", 1)[0]
    tail = review_user_tail(proposed, [f"{c.label}. {option_text(c)}" for c in request.candidates])
    return [
        {"role": "system", "content": static_part(request, REVIEW_SYSTEM)},
        {"role": "user", "content": f"{body}\n{tail}"},
    ]


async def local_review(
    client: ChatClient,
    mode: JsonMode,
    request: DecisionRequest,
    proposed: str | None,
    *,
    agent: str,
    slot: int | None,
) -> tuple[Review, JsonAnswer]:
    labels = [c.label for c in request.candidates]
    obs = request.observation
    ans = await json_chat(
        client,
        review_messages(request, proposed),
        review_schema(labels),
        name="review",
        max_tokens=REVIEW_MAX_TOKENS,
        tag=CallTag(agent, request.role, obs.episode, obs.round, "review"),
        mode=mode,
        slot=slot,
    )
    return check_review(ans.value, labels), ans


__all__ = ["Hmas2Policy", "local_review", "review_messages"]
