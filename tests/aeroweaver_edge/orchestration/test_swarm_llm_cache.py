"""A swarm deciding through an LLM endpoint with cache slots: every UAV's decisions go to its
own slot, each agent's context carries its own history, and cached prompt tokens are
accounted per decision and in the run summary (against the loopback fake provider, which
reports cached tokens as llama-server does)."""

from __future__ import annotations

import re

from aeroweaver_edge.agent.prompt import HISTORY_HEADER
from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy, RecordedRequest
from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm

ROUNDS = 4


def shown_history(r: RecordedRequest) -> list[str]:
    """The history lines of a decision request (between its header and the observation;
    options that moved after the history are not history lines)."""
    user = str(r.body["messages"][-1]["content"])
    part = user[user.index(HISTORY_HEADER) : user.index("\nyou ")].splitlines()[1:]
    return [h for h in part if re.match(r"r\d+ ", h)]


def decisions(fake: FakeProvider) -> list[RecordedRequest]:
    return [
        r
        for r in fake.requests
        if r.path.endswith("/chat/completions") and "## Options" in str(r.body["messages"])
    ]


async def test_slots_history_and_cached_tokens_in_an_llm_swarm() -> None:
    policy = Policy(prefer="A", usage="llama", llama_extras=True)
    async with FakeProvider(policy, n_slots=3) as fake:
        llm = LLMConfig(base_url=fake.base_url, model="fake-model")
        opts = SwarmOptions(
            uavs=3, seed=1, max_rounds=ROUNDS, selector="llm", beta=0.0, llm=llm, slots=True
        )
        data = (await run_swarm(opts)).as_dict()
        made = decisions(fake)
        seeds = [
            r.body["id_slot"]
            for r in fake.requests
            if r.path.endswith("/chat/completions") and "## Options" not in str(r.body["messages"])
            and "id_slot" in r.body
        ]  # fmt: skip

    assert len(made) == 3 * ROUNDS == data["llm_calls"]
    rounds_seen: dict[str, list[int]] = {}
    for r in made:
        user = r.body["messages"][-1]["content"]
        uav = re.match(r"You are UAV (uav\d)\.", user)
        assert uav is not None
        assert r.body["id_slot"] == int(uav.group(1)[-1])  # uav<i> always in slot i
        history = shown_history(r)
        rnd = len(rounds_seen.get(uav.group(1), []))  # a UAV's requests come round by round
        assert [h.split()[0] for h in history] == [f"r{i}" for i in range(rnd)]  # its own past
        assert all(re.fullmatch(r"-?\d+(\.\d)?", h.split()[-1]) for h in history)  # + reward
        rounds_seen.setdefault(uav.group(1), []).append(rnd)
    assert rounds_seen == {f"uav{i}": list(range(ROUNDS)) for i in range(3)}

    cached = sum(r.cached_tokens or 0 for r in made)
    tokens, per = data["tokens"], data["tokens_per_decision"]
    assert tokens["prompt_cached"] == cached
    assert 0 < cached < tokens["prompt"]
    assert per["prompt_cached"] == round(cached / len(made), 1)
    assert per["prompt_uncached"] == round((tokens["prompt"] - cached) / len(made), 1)
    # Round 0: the role's prefix was computed once before the episode and copied into every
    # slot, so even the first decisions reuse the system prompt and most of the agent part.
    system = len(made[0].body["messages"][0]["content"]) // 4
    first = [r.cached_tokens or 0 for r in made if not shown_history(r)]
    assert len(first) == 3
    assert min(first) > system
    assert seeds == [0]  # one prefill for the one coverage role, in uav0's slot
    assert set(fake.slot_files) == {"seed-0.bin"}
    # From round 1 on each UAV's own prefix (system + agent part) comes from its slot.
    later = [r.cached_tokens or 0 for r in made if shown_history(r)]
    assert min(later) > system
