"""Start a baseline's two halves: the central node (one per run) and a UAV's remote selector.

``CentralBaseline`` is what a simulated run takes (``SwarmOptions.central``, the runtime's
``orchestration.central.CentralRole``); ``open_remote_selector`` is registered as the
``centralized`` and ``hmas2`` selectors (entry points ``aeroweaver.selectors``)."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager
from dataclasses import dataclass
from typing import Any

from aeroweaver_edge.config import LLMConfig, MeshConfig, UavConfig
from aeroweaver_edge.contracts.wire import HeaderFactory
from aeroweaver_edge.mesh.secured import boot_headers
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_lab.baselines import CENTRAL_NODE, Baseline
from aeroweaver_lab.baselines.central import CentralNode, CentralPolicy, CentralRound
from aeroweaver_lab.baselines.remote import RemoteSelector


def skill_doc_renderer() -> Callable[[list[str]], list[str]]:
    from aeroweaver_edge.skills import load_skills

    registry = load_skills()

    def docs(names: list[str]) -> list[str]:
        return [registry.get(n).prompt_text() for n in names if n in registry]

    return docs


def make_policy(mode: str, llm: LLMConfig, *, review_wait_s: float) -> CentralPolicy:
    from aeroweaver_edge.llm.client import ChatClient

    client = ChatClient.from_config(llm)
    if mode == "centralized":
        from aeroweaver_lab.baselines.centralized import CentralizedPolicy

        return CentralizedPolicy(client, slot=llm.slot)
    if mode == "hmas2":
        from aeroweaver_lab.baselines.hmas2 import Hmas2Policy

        return Hmas2Policy(client, slot=llm.slot, review_wait_s=review_wait_s)
    raise ValueError(f"unknown baseline {mode!r}")


@contextlib.asynccontextmanager
async def open_central(
    mode: str,
    mesh_cfg: MeshConfig,
    swarm: str,
    llm: LLMConfig,
    *,
    gather_s: float = 3.0,
    review_wait_s: float | None = None,
    on_round: Callable[[CentralRound], None] | None = None,
) -> AsyncIterator[CentralNode]:
    """The central node on its own mesh session (identity ``central``), closed on exit."""
    policy = make_policy(mode, llm, review_wait_s=review_wait_s or llm.deadline_s + 5.0)
    async with contextlib.AsyncExitStack() as stack:
        stack.push_async_callback(policy.aclose)
        mesh = await Mesh.open(mesh_cfg, node_id=CENTRAL_NODE)
        stack.push_async_callback(mesh.aclose)
        headers = await asyncio.to_thread(boot_headers, mesh_cfg, CENTRAL_NODE)
        docs = await asyncio.to_thread(skill_doc_renderer)  # reads the skill packages
        node = CentralNode(
            mesh,
            swarm,
            policy,
            docs,
            gather_s=gather_s,
            on_round=on_round,
            headers=headers,
        )
        await node.start()
        stack.push_async_callback(node.aclose)
        yield node


@dataclass(frozen=True)
class CentralBaseline:
    """A baseline's central node for a simulated run (``SwarmOptions.central``)."""

    selector: Baseline  # the UAVs' selector, and the node's policy
    gather_s: float = 3.0  # the node waits this long for a round's asks

    def open(
        self,
        mesh: MeshConfig,
        swarm: str,
        llm: LLMConfig,
        on_round: Callable[[Any], None] | None,
    ) -> AbstractAsyncContextManager[CentralNode]:
        return open_central(
            self.selector, mesh, swarm, llm, gather_s=self.gather_s, on_round=on_round
        )


@contextlib.asynccontextmanager
async def open_remote_selector(
    cfg: UavConfig, mesh: Mesh, headers: HeaderFactory
) -> AsyncIterator[RemoteSelector]:
    """The remote selector of ``cfg.agent.selector`` (centralized / hmas2) for one UAV."""
    client = None
    if cfg.agent.selector == "hmas2":
        from aeroweaver_edge.llm.client import ChatClient

        if cfg.llm.base_url is None:
            raise ValueError("hmas2 needs an LLM endpoint (llm.base_url) for the local review")
        client = ChatClient.from_config(cfg.llm)
    selector = RemoteSelector(
        mesh,
        cfg.swarm,
        cfg.uav,
        headers,
        mode=cfg.agent.selector,
        review_client=client,
        review_slot=cfg.llm.slot,
    )
    await selector.start()
    try:
        yield selector
    finally:
        await selector.aclose()


__all__ = [
    "CentralBaseline",
    "make_policy",
    "open_central",
    "open_remote_selector",
    "skill_doc_renderer",
]
