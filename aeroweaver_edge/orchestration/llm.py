"""One LLM endpoint for a whole simulated run: the configured one or the embedded server."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from typing import TYPE_CHECKING, Literal

from aeroweaver_edge.config import LLMConfig

if TYPE_CHECKING:
    from aeroweaver_edge.llm.probe import ProbeResult
    from commander.plan import MissionPlan

Source = Literal["scripted", "endpoint", "embedded"]

HONESTY_NOTE: dict[Source, str] = {
    "scripted": "Decisions come from the task's scripted reference policy, not an LLM: these "
    "returns are a sanity bound and say nothing about LLM quality.",
    "embedded": "Decisions come from SmolLM2-135M (embedded plumbing demo; strong position bias, "
    "no useful judgement): these returns are not evidence about LLM-driven swarm performance.",
    "endpoint": "Decisions come from the configured LLM endpoint.",
}


@contextlib.asynccontextmanager
async def shared_llm(
    llm: LLMConfig, *, needed: bool, n_parallel: int = 1, slot_ctx: int | None = None
) -> AsyncIterator[tuple[LLMConfig, Source]]:
    """The endpoint every daemon (and the Commander) uses: ``llm`` when it names a URL, else
    the embedded server, started here and stopped on exit, with ``n_parallel`` cache slots
    (one per UAV: each agent's prefix stays cached) of ``slot_ctx`` tokens each (None: the
    server's default). ``needed=False``: no LLM at all."""
    if not needed:
        yield llm, "scripted"
        return
    if llm.base_url is not None:
        yield llm, "endpoint"
        return
    from aeroweaver_edge.llm.embedded import EmbeddedServer

    n = max(1, n_parallel)
    async with EmbeddedServer(n_parallel=n, n_ctx=n * slot_ctx if slot_ctx else None) as server:
        yield (
            llm.model_copy(update={"base_url": server.base_url, "model": server.model}),
            "embedded",
        )


async def probe(llm: LLMConfig) -> ProbeResult:
    """The endpoint probe's verdict (``line()`` is the one-line form)."""
    from aeroweaver_edge.llm.client import ChatClient
    from aeroweaver_edge.llm.probe import probe_endpoint

    async with ChatClient.from_config(llm) as client:
        return await probe_endpoint(client)


__all__ = ["HONESTY_NOTE", "Source", "probe", "shared_llm"]


async def seed_role_slots(
    llm: LLMConfig, plan: MissionPlan, uavs: list[str], n_slots: int, *, history: bool
) -> int:
    """Compute each role's prompt prefix once and copy it into its UAVs' cache slots (UAV i
    uses slot ``i % n_slots``), so round 0 does not process the same system prompt once per
    UAV. Best effort (``llm/slot_seed.py``); returns how many slots were seeded."""
    from aeroweaver_edge.agent.prompt import prefix_messages
    from aeroweaver_edge.contracts.observation import MissionView
    from aeroweaver_edge.llm.slot_seed import SlotGroup, seed_slots
    from aeroweaver_edge.skills import load_skills

    if llm.base_url is None:
        return 0
    registry = await asyncio.to_thread(load_skills)  # reads every skill package from disk
    groups: dict[tuple[str, str, tuple[str, ...]], tuple[list[dict[str, str]], list[int]]] = {}
    for i, uav in enumerate(uavs):
        a = plan.assignments.get(uav)
        if a is None:
            continue
        key = (a.role, a.local_goal, tuple(a.skills))
        if key not in groups:
            view = MissionView(plan.mission_id, plan.task, plan.text, a.role, a.local_goal,
                               tuple(a.skills), tuple(plan.constraints))  # fmt: skip
            docs = [registry.get(s).prompt_text() for s in a.skills if s in registry]
            groups[key] = (prefix_messages(view, uav, docs, history=history), [])
        groups[key][1].append(i % n_slots)
    root = llm.base_url.removesuffix("/v1")
    return await seed_slots(root, llm.model, [SlotGroup(m, sl) for m, sl in groups.values()])
