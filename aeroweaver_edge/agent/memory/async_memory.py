"""The asyncio face of experience memory (agent.memory): one worker thread owns it.

Kept apart so the synchronous memory (simulator, tools, tests) carries no executor.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from aeroweaver_edge.agent.estimators import PAPER, Estimator
from aeroweaver_edge.agent.memory.records import Neighbour, StoredRecord
from aeroweaver_edge.config import AgentConfig
from aeroweaver_edge.contracts.wire import ExperienceRecord

if TYPE_CHECKING:
    from aeroweaver_edge.agent.memory.experience import ExperienceMemory

T = TypeVar("T")


class AsyncExperienceMemory:
    """``ExperienceMemory`` for the asyncio daemon: one worker thread owns the SQLite
    connection (created in that thread) and runs every call in FIFO order, so the event
    loop never blocks on disk and writes keep their order. Create with ``open``."""

    def __init__(self, executor: ThreadPoolExecutor, memory: ExperienceMemory) -> None:
        self._executor = executor
        self._mem = memory
        self._closed = False

    @classmethod
    async def open(
        cls,
        path: str | Path | None = None,
        *,
        gamma: float = 0.95,
        neighbourhood: int = 32,
        finalised_only: bool = False,
        durable: bool = False,
        run: str | None = None,
        required: bool = False,
        estimator: Estimator = PAPER,
    ) -> AsyncExperienceMemory:
        from aeroweaver_edge.agent.memory.experience import ExperienceMemory

        executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="aw-memory")
        loop = asyncio.get_running_loop()
        try:
            memory = await loop.run_in_executor(
                executor,
                lambda: ExperienceMemory(
                    path,
                    gamma=gamma,
                    neighbourhood=neighbourhood,
                    finalised_only=finalised_only,
                    durable=durable,
                    run=run,
                    required=required,
                    estimator=estimator,
                ),
            )
        except BaseException:
            executor.shutdown(wait=False)
            raise
        return cls(executor, memory)

    @classmethod
    async def from_config(
        cls, cfg: AgentConfig, *, run: str | None = None
    ) -> AsyncExperienceMemory:
        return await cls.open(
            cfg.memory_path,
            gamma=cfg.gamma,
            neighbourhood=cfg.neighbourhood,
            finalised_only=cfg.finalised_only,
            run=run or cfg.run_id,
            required=cfg.memory_required,
            estimator=Estimator.parse(cfg.estimator),
        )

    @property
    def run(self) -> str:
        return self._mem.run

    @property
    def sync(self) -> ExperienceMemory:
        """The wrapped memory, for attributes only (calling it from the loop would block)."""
        return self._mem

    async def _run(self, fn: Callable[[], T]) -> T:
        if self._closed:
            raise RuntimeError("experience memory is closed")
        return await asyncio.get_running_loop().run_in_executor(self._executor, fn)

    async def append(
        self,
        *,
        task: str,
        role: str,
        uav: str,
        episode: int,
        round: int,
        state_text: str,
        skill: str,
        invocation: str,
    ) -> bool:
        m = self._mem
        return await self._run(
            lambda: m.append(
                task=task,
                role=role,
                uav=uav,
                episode=episode,
                round=round,
                state_text=state_text,
                skill=skill,
                invocation=invocation,
            )
        )

    async def add_reward(
        self, uav: str, episode: int, round: int, reward: float, source: str
    ) -> bool:
        return await self._run(lambda: self._mem.add_reward(uav, episode, round, reward, source))

    async def finalise(self, uav: str, episode: int) -> int:
        return await self._run(lambda: self._mem.finalise(uav, episode))

    async def ingest(self, record: ExperienceRecord) -> bool:
        return await self._run(lambda: self._mem.ingest(record))

    async def ingest_many(self, records: Iterable[ExperienceRecord]) -> int:
        batch = list(records)  # materialise here: the iterable may not be thread-safe
        return await self._run(lambda: self._mem.ingest_many(batch))

    async def store_peers(self, batch: Iterable[tuple[ExperienceRecord, bool]]) -> int:
        items = list(batch)  # materialise here: the iterable may not be thread-safe
        return await self._run(lambda: self._mem.store_peers(items))

    async def credit_peer(self, record: ExperienceRecord) -> int:
        return await self._run(lambda: self._mem.credit_peer(record))

    async def warm(self, task: str, role: str) -> int:
        return await self._run(lambda: self._mem.warm(task, role))

    async def get(
        self, uav: str, episode: int, round: int, *, run: str | None = None
    ) -> StoredRecord | None:
        return await self._run(lambda: self._mem.get(uav, episode, round, run=run))

    async def export(
        self, uav: str, episode: int, *, final_only: bool = True
    ) -> list[StoredRecord]:
        return await self._run(lambda: self._mem.export(uav, episode, final_only=final_only))

    async def export_final(self, uav: str, episode: int) -> list[StoredRecord]:
        return await self.export(uav, episode, final_only=True)

    async def advantages(
        self, task: str, role: str, state_text: str, skills: Iterable[str]
    ) -> dict[str, float]:
        names = list(skills)  # materialise here: the iterable may not be thread-safe
        return await self._run(lambda: self._mem.advantages(task, role, state_text, names))

    async def neighbourhood_of(self, task: str, role: str, state_text: str) -> list[Neighbour]:
        return await self._run(lambda: self._mem.neighbourhood_of(task, role, state_text))

    async def count(self) -> int:
        return await self._run(lambda: len(self._mem))

    async def aclose(self) -> None:
        """Close the database in its thread, then stop the thread (idempotent)."""
        if self._closed:
            return
        try:
            await self._run(self._mem.close)
        finally:
            self._closed = True
            self._executor.shutdown(wait=True)  # the queue is empty: returns at once


__all__ = ["AsyncExperienceMemory"]
