"""The LLM selector end to end against the loopback fake, and the prompt it sends."""

from __future__ import annotations

import time
from collections.abc import AsyncIterator

import pytest

from aeroweaver_edge.agent.llm_selector import LLMSelector
from aeroweaver_edge.agent.prompt import HISTORY_HEADER, OPTIONS_HEADER, build_messages
from aeroweaver_edge.agent.scoring import choose
from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.contracts.observation import Observation, VehicleState
from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest, Selector
from aeroweaver_edge.contracts.wire import InboxMessage
from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.llm.fake_provider import QUIRKS, FakeProvider, Policy
from aeroweaver_edge.llm.probe import ProbeResult, probe_endpoint

CANDIDATES = [
    Candidate("A", "cover_landmark", {"target_id": "L1"}, "cover_landmark(target_id=L1)"),
    Candidate("B", "cover_landmark", {"target_id": "L2"}, "cover_landmark(target_id=L2)"),
    Candidate("C", "explore_local", {"heading": "north"}, "explore_local(heading=north)"),
    Candidate("D", "hold_position", {}, "hold_position()"),
]
LABELS = [c.label for c in CANDIDATES]


def request(
    round_no: int = 3,
    messages: tuple[InboxMessage, ...] = (),
    uav: str = "uav1",
    candidates: list[Candidate] | None = None,
    history: tuple[str, ...] | None = None,
) -> DecisionRequest:
    obs = Observation(
        uav=uav,
        episode=7,
        round=round_no,
        own=VehicleState(pos=(0.0, 0.0, -5.0), vel=(0.0, 0.0, 0.0)),
        messages=messages,
    )
    return DecisionRequest(
        observation=obs,
        mission_text="Cover every landmark.",
        role="searcher",
        local_goal="Take the nearest unclaimed landmark.",
        constraints=("stay inside the arena",),
        skill_docs=("### cover_landmark\nFly to a landmark.", "### hold_position\nStay."),
        observation_text=f"round {round_no}; landmark L1: 20 m N",
        candidates=CANDIDATES if candidates is None else candidates,
        history=history,
    )


# ------------------------------------------------------------------ selector


@pytest.fixture
async def fp() -> AsyncIterator[FakeProvider]:
    async with FakeProvider(Policy(prefer="C")) as server:
        yield server


def selector(fp: FakeProvider, probe: ProbeResult | None, **cfg: object) -> LLMSelector:
    config = LLMConfig(base_url=fp.base_url, model="fake", deadline_s=1.0, retries=0, **cfg)
    return LLMSelector(ChatClient.from_config(config), config, probe)


OK = ProbeResult("ok", 0.8)


async def test_selector_is_a_selector_and_scores_end_to_end(fp: FakeProvider) -> None:
    sel = selector(fp, OK, temperature=0.5)
    as_port: Selector = sel  # static check: mypy verifies the protocol
    assert as_port.name == "llm:fake"
    try:
        scores = await sel.score(request())
    finally:
        await sel.aclose()
    assert scores.error is None
    assert scores.logprobs_usable
    assert choose(scores, LABELS, {}, beta=0.8).label == "C"
    assert set(scores.logprobs) <= set(LABELS)
    assert scores.prompt_tokens > 0
    assert scores.latency_s > 0
    assert scores.extra["probe"] == "ok"
    body = fp.chat_bodies()[0]
    assert body["logprobs"] is True
    assert body["top_logprobs"] == 20
    assert body["max_tokens"] == 1
    assert body["temperature"] == 0.5
    assert body["messages"] == build_messages(request())


async def _three_agents_three_rounds(fp: FakeProvider, slots: bool) -> list[list[int]]:
    """Cached prompt tokens per round and agent, agents interleaved as in a swarm round."""
    sels = [selector(fp, OK, slot=i if slots else None) for i in range(3)]
    cached: list[list[int]] = []
    try:
        for rnd in range(3):
            history = tuple(f"r{r} explore_local() -1.00" for r in range(rnd))
            cached.append(
                [
                    (await sel.score(request(rnd, uav=f"uav{i}", history=history))).cached_tokens
                    for i, sel in enumerate(sels)
                ]
            )
    finally:
        for sel in sels:
            await sel.aclose()
    return cached


async def test_a_configured_slot_is_sent_with_every_decision_and_keeps_its_prefix() -> None:
    policy = Policy(prefer="C", usage="llama", llama_extras=True)
    async with FakeProvider(policy, n_slots=3) as fp:
        pinned = await _three_agents_three_rounds(fp, slots=True)
        bodies = fp.chat_bodies()
        served = list(fp.slots_served)
    assert [b["id_slot"] for b in bodies] == [0, 1, 2] * 3
    assert served == [0, 1, 2] * 3
    async with FakeProvider(policy, n_slots=3) as fp:
        unpinned = await _three_agents_three_rounds(fp, slots=False)
        assert all("id_slot" not in b for b in fp.chat_bodies())
    shared = unpinned[0][1]  # the system prompt (and "You are UAV uav"), common to all
    assert shared >= len(build_messages(request())[0]["content"]) // 4
    # Unpinned: the agents share one slot and evict each other's agent part every time.
    assert unpinned[1:] == [[shared] * 3] * 2
    # Pinned: each agent also keeps its own agent part, which grows with its history.
    assert pinned[0] == [0, 0, 0]
    assert all(shared < a < b for a, b in zip(pinned[1], pinned[2], strict=True))


async def test_usage_is_journaled_per_agent_role_episode(fp: FakeProvider) -> None:
    sel = selector(fp, OK)
    try:
        await sel.score(request(1))
        await sel.score(request(2))
    finally:
        await sel.aclose()
    ledger = sel.client.ledger
    assert ledger.by_agent()["uav1"].calls == 2
    assert ledger.by_role()["searcher"].calls == 2
    assert ledger.by_episode()[7].prompt_tokens > 0
    assert [e.tag.round for e in ledger.journal] == [1, 2]
    assert {e.tag.purpose for e in ledger.journal} == {"decide"}


@pytest.mark.parametrize("quirk", ["server_error", "hang", "bad_json", "reject_logprobs"])
async def test_any_client_error_becomes_a_hold_not_an_exception(
    fp: FakeProvider, quirk: str
) -> None:
    fp.policy = QUIRKS[quirk]
    sel = selector(fp, OK)
    started = time.perf_counter()
    try:
        scores = await sel.score(request())
    finally:
        await sel.aclose()
    assert time.perf_counter() - started < 2.0  # the 1 s deadline plus scheduling slack
    assert scores.logprobs == {}
    assert scores.error
    assert choose(scores, LABELS, {}, beta=0.8).label is None


async def test_endpoint_down_is_a_hold() -> None:
    async with FakeProvider() as fp:
        url = fp.base_url
    config = LLMConfig(base_url=url, model="fake", deadline_s=1.0, retries=0)
    sel = LLMSelector(ChatClient.from_config(config), config, OK)
    try:
        scores = await sel.score(request())
    finally:
        await sel.aclose()
    assert scores.error is not None
    assert "cannot connect" in scores.error
    assert scores.extra["error_kind"] == "LLMUnreachable"


async def test_no_candidates_is_a_hold_without_a_request(fp: FakeProvider) -> None:
    sel = selector(fp, OK)
    try:
        scores = await sel.score(request(candidates=[]))
    finally:
        await sel.aclose()
    assert scores.error
    assert fp.chat_calls == 0


async def test_rejected_probe_sends_no_logprobs_and_uses_the_text_label(fp: FakeProvider) -> None:
    fp.policy = Policy(prefer="B", reject_logprobs=True)
    sel = selector(fp, ProbeResult("rejected", 0.0, "HTTP 400"))
    try:
        scores = await sel.score(request())
    finally:
        await sel.aclose()
    body = fp.chat_bodies()[0]
    assert "logprobs" not in body
    assert "top_logprobs" not in body
    assert not scores.logprobs_usable
    c = choose(scores, LABELS, {"A": 10.0}, beta=0.8)
    assert c.label == "B"
    assert "correction off" in c.reason


@pytest.mark.parametrize(
    ("kind", "policy"),
    [("degenerate", QUIRKS["degenerate"]), ("low_label_mass", Policy(prefer="B"))],
)
async def test_probe_not_ok_means_text_label(fp: FakeProvider, kind: str, policy: Policy) -> None:
    fp.policy = policy
    sel = selector(fp, ProbeResult(kind, 0.0))  # type: ignore[arg-type]
    try:
        scores = await sel.score(request())
    finally:
        await sel.aclose()
    assert not scores.logprobs_usable
    assert choose(scores, LABELS, {"A": 10.0}, beta=0.8).label == "B"


async def test_unprobed_selector_settles_from_its_first_answer(fp: FakeProvider) -> None:
    sel = selector(fp, ProbeResult("unreachable", 0.0, "down at start-up"))
    try:
        scores = await sel.score(request())
        assert sel.probe is not None
        assert sel.probe.kind == "ok"
        assert scores.logprobs_usable
    finally:
        await sel.aclose()


async def test_unprobed_selector_learns_rejection_from_a_400(fp: FakeProvider) -> None:
    """The 400 is retried once without logprob parameters; its answer proves the cause and
    already decides this round."""
    fp.policy = Policy(prefer="B", reject_logprobs=True)
    sel = selector(fp, None)
    try:
        first = await sel.score(request())
        assert first.error is None
        assert sel.probe is not None
        assert sel.probe.kind == "rejected"
        assert "answered without them" in sel.probe.detail
        second = await sel.score(request())
    finally:
        await sel.aclose()
    assert choose(first, LABELS, {}, beta=0.8).label == "B"
    assert second.error is None
    assert choose(second, LABELS, {}, beta=0.8).label == "B"
    bodies = fp.chat_bodies()
    assert len(bodies) == 3  # refused, retried without logprobs, then never asked again
    assert "logprobs" in bodies[0]
    assert "logprobs" not in bodies[1]
    assert "logprobs" not in bodies[2]
    assert sel.requests_sent == 3


async def test_unprobed_selector_settles_degenerate(fp: FakeProvider) -> None:
    fp.policy = QUIRKS["degenerate"]
    sel = selector(fp, None)
    try:
        scores = await sel.score(request())
    finally:
        await sel.aclose()
    assert sel.probe is not None
    assert sel.probe.kind == "degenerate"
    assert choose(scores, LABELS, {}, beta=0.8).label == "B"


async def test_unprobed_selector_settles_low_label_mass_for_a_base_model(fp: FakeProvider) -> None:
    fp.policy = Policy(missing=tuple(LABELS))  # labels far below the top list
    sel = selector(fp, None)
    try:
        scores = await sel.score(request())
    finally:
        await sel.aclose()
    assert sel.probe is not None
    assert sel.probe.kind == "low_label_mass"
    assert not scores.logprobs_usable


async def test_probe_then_select_with_one_client(fp: FakeProvider) -> None:
    config = LLMConfig(base_url=fp.base_url, model="fake", deadline_s=1.0)
    client = ChatClient.from_config(config)
    result = await probe_endpoint(client)
    sel = LLMSelector(client, config, result)
    try:
        scores = await sel.score(request())
    finally:
        await sel.aclose()
    assert result.kind == "ok"
    assert choose(scores, LABELS, {}, beta=0.8).label == "C"
    assert [e.tag.purpose for e in client.ledger.journal] == ["probe", "decide"]


async def test_agent_name_overrides_the_ledger_tag(fp: FakeProvider) -> None:
    config = LLMConfig(base_url=fp.base_url, model="fake")
    sel = LLMSelector(ChatClient.from_config(config), config, OK, agent="uav9-daemon")
    try:
        await sel.score(request())
    finally:
        await sel.aclose()
    assert list(sel.client.ledger.by_agent()) == ["uav9-daemon"]
    assert OK.summary() == OK.line()


async def test_shared_client_is_not_closed(fp: FakeProvider) -> None:
    config = LLMConfig(base_url=fp.base_url, model="fake")
    client = ChatClient.from_config(config)
    sel = LLMSelector(client, config, OK, owns_client=False)
    await sel.aclose()
    try:
        await client.chat([{"role": "user", "content": "hi"}])  # still usable
    finally:
        await client.aclose()


@pytest.mark.parametrize(
    ("letters", "budget"),
    [
        (None, None),  # the endpoint cannot tokenize: no limit known
        (tuple("ABCDEFGHIJKLMNOPQRSTUVWXYZ"), 26),
        (("A", "B", "C", "E"), 3),  # "D" is two tokens: labels stop before it
        ((), 0),
    ],
)
async def test_label_budget_follows_the_single_token_check(
    fp: FakeProvider, letters: tuple[str, ...] | None, budget: int | None
) -> None:
    probe = ProbeResult(kind="ok", label_mass=0.9, single_token_labels=letters)
    sel = selector(fp, probe)
    try:
        assert sel.label_budget == budget
    finally:
        await sel.aclose()


async def test_probe_reports_two_token_letters_from_the_endpoint(fp: FakeProvider) -> None:
    fp.policy = Policy(tokenizer="split")
    async with ChatClient(fp.base_url, "fake-model") as client:
        probe = await probe_endpoint(client)
    assert probe.single_token_labels == ()
    sel = selector(fp, probe)
    try:
        assert sel.label_budget == 0
    finally:
        await sel.aclose()


async def test_options_that_keep_changing_are_sent_after_the_history(fp: FakeProvider) -> None:
    """The selector places each UAV's options (``prompt.OptionPlacement``): before the
    history while stable, after it from the third change in four rounds."""
    sel = selector(fp, OK)
    sets = [CANDIDATES, CANDIDATES[1:], CANDIDATES, CANDIDATES[1:]]
    try:
        for rnd, cands in enumerate(sets):
            history = tuple(f"r{r} explore_local() -1" for r in range(rnd))
            await sel.score(request(rnd, candidates=cands, history=history))
    finally:
        await sel.aclose()
    users = [str(b["messages"][-1]["content"]) for b in fp.chat_bodies()]
    after = [u.index(OPTIONS_HEADER) > u.index(HISTORY_HEADER) for u in users]
    assert after == [False, False, False, True]
