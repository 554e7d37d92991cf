"""A central node beside a simulated swarm: the seam the paper's baselines plug into.

The runtime has no central brain; a benchmark baseline (``aeroweaver_lab.baselines``) adds
one as a selector: its node runs on its own mesh identity (``central``) and every UAV's
selector, named by ``selector``, asks it each round. ``run_swarm`` only opens the node with
the run's network and LLM and folds what it spent into the summary
(``swarm.fold_central_tokens``); it never knows which baseline it is.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractAsyncContextManager
from typing import Any, Protocol

from aeroweaver_edge.config import LLMConfig, MeshConfig


class CentralNode(Protocol):
    def totals(self) -> dict[str, Any]:
        """``{"tokens": {prompt, prompt_cached, completion, total}, "llm_calls": n,
        "by_episode": {"0": {"tokens": n, ...}}, ...}``: what the node spent."""
        ...


class CentralRole(Protocol):
    """What a run needs to fly under a central node."""

    @property
    def selector(self) -> str:
        """The UAVs' ``[agent] selector`` (the name their selector is registered under)."""
        ...

    def open(
        self,
        mesh: MeshConfig,
        swarm: str,
        llm: LLMConfig,
        on_round: Callable[[Any], None] | None,
    ) -> AbstractAsyncContextManager[CentralNode]:
        """The node on its own session, closed on exit; ``on_round`` gets one record per
        round it decided (the trace's ``central`` field)."""
        ...


__all__ = ["CentralNode", "CentralRole"]
