"""Fixtures for the Commander harness tests: a real loopback LLM that answers in script order."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import replace
from typing import Any

import pytest

from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
from aeroweaver_edge.skills import SkillRegistry, load_skills


class ScriptedProvider(FakeProvider):
    """FakeProvider whose successive chat answers follow a script (the last entry repeats):
    a string is the generated content, an int is an HTTP error status. Everything else
    (HTTP on loopback, usage, request recording) is the real fake."""

    def __init__(self, answers: Sequence[str | int]) -> None:
        super().__init__(Policy())
        self.answers = list(answers)
        self.served = 0

    def _chat(self, policy: Policy, body: Any) -> Any:
        answer = self.answers[min(self.served, len(self.answers) - 1)]
        self.served += 1
        if isinstance(answer, int):
            return super()._chat(replace(policy, status=answer), body)
        return super()._chat(replace(policy, content=answer), body)


@pytest.fixture
async def llm() -> AsyncIterator[Callable[..., Any]]:
    """``fp, client = await llm([...answers])``; everything is closed after the test."""
    opened: list[tuple[ScriptedProvider, ChatClient]] = []

    async def make(answers: Sequence[str | int]) -> tuple[ScriptedProvider, ChatClient]:
        fp = await ScriptedProvider(answers).start()
        client = ChatClient(fp.base_url, "fake", retries=0, deadline_s=5.0)
        opened.append((fp, client))
        return fp, client

    yield make
    for fp, client in opened:
        await client.aclose()
        await fp.close()


@pytest.fixture(scope="session")
def registry() -> SkillRegistry:
    return load_skills()
