"""Centralized baseline: one LLM call per round chooses an option for every controlled UAV.

The prompt holds the mission, the team's roles and goals, the full skill catalogue and, per
UAV, what it perceived and received and its lettered options (its ``CentralAsk``); the
answer is one JSON object ``{"uav0": "A", ...}`` requested with a JSON schema that allows,
per UAV, only that UAV's letters. Each UAV's letter is checked again: a missing, foreign or
malformed letter makes that UAV alone hold; a failed call holds the round's UAVs as an LLM
failure.
"""

from __future__ import annotations

from aeroweaver_edge.llm.client import CallTag, ChatClient
from aeroweaver_lab.baselines.central import (
    CallRecord,
    CentralIO,
    CentralRound,
    RoundAsks,
    Verdict,
)
from aeroweaver_lab.baselines.json_chat import JsonAnswer, JsonMode, json_chat
from aeroweaver_lab.baselines.protocol import (
    Mission,
    check_plan,
    labels_of,
    plan_max_tokens,
    plan_messages,
    team_schema,
)

ANSWER_CHARS = 400


def call_record(rnd: RoundAsks, stage: str, ans: JsonAnswer) -> CallRecord:
    return CallRecord(
        rnd.episode,
        rnd.round,
        stage,
        prompt=ans.prompt_tokens,
        cached=ans.cached_tokens,
        completion=ans.completion_tokens,
        requests=ans.requests,
        latency_s=ans.latency_s,
        error=ans.error,
        answer=ans.text[:ANSWER_CHARS],
    )


async def plan_call(
    client: ChatClient,
    mode: JsonMode,
    rnd: RoundAsks,
    mission: Mission,
    stage: str,
    slot: int | None,
    messages: list[dict[str, str]] | None = None,
) -> tuple[dict[str, str | None], CallRecord, list[dict[str, str]]]:
    """One team call (plan, revision or the centralized decision): per-UAV labels (None:
    invalid), its record, and the messages it sent."""
    labels = {a.uav: labels_of(a.options) for a in rnd.asks}
    msgs = messages or plan_messages(mission, rnd.episode, rnd.round, rnd.asks)
    ans = await json_chat(
        client,
        msgs,
        team_schema(labels),
        name="team_plan",
        max_tokens=plan_max_tokens(len(rnd.asks)),
        tag=CallTag("central", "central", rnd.episode, rnd.round, stage),
        mode=mode,
        slot=slot,
    )
    rec = call_record(rnd, stage, ans)
    if ans.error is not None:
        return dict.fromkeys(labels), rec, msgs
    check = check_plan(ans.value, labels)
    rec.invalid = dict(check.invalid)
    return check.labels, rec, msgs


class CentralizedPolicy:
    name = "centralized"

    def __init__(self, client: ChatClient, *, slot: int | None = None) -> None:
        self.client = client
        self.slot = slot
        self.mode = JsonMode()

    async def decide(
        self, rnd: RoundAsks, mission: Mission, io: CentralIO, record: CentralRound
    ) -> dict[str, Verdict]:
        labels, rec, _ = await plan_call(self.client, self.mode, rnd, mission, "decide", self.slot)
        record.calls.append(rec)
        if rec.error is not None:
            return {u: Verdict(None, rec.error, "central call failed") for u in rnd.uavs}
        return {
            u: Verdict(labels[u], None, "central" if labels[u] else rec.invalid.get(u, "invalid"))
            for u in rnd.uavs
        }

    async def aclose(self) -> None:
        await self.client.aclose()


__all__ = ["CentralizedPolicy", "call_record", "plan_call"]
