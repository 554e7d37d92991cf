"""Owned tasks: ``cancel_all`` cancels, names a task that lost its cancel, and keeps
waiting when its owner is stopped again."""

from __future__ import annotations

import asyncio
import contextlib

import pytest

from aeroweaver_edge.runtime import lifecycle


async def test_cancel_all_recancels_a_task_that_swallowed_its_cancel(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A task that loses one cancel (as 3.11's ``wait_for`` can make it) is named and
    cancelled again, so the shutdown that owns it ends instead of waiting forever."""
    monkeypatch.setattr(lifecycle, "CANCEL_GRACE_S", 0.2)
    swallowed = asyncio.Event()

    async def stubborn() -> None:
        try:
            await asyncio.sleep(3600)
        except asyncio.CancelledError:
            swallowed.set()  # ... and carries on as if nothing happened
        await asyncio.sleep(3600)

    task = asyncio.create_task(stubborn(), name="stubborn")
    await asyncio.sleep(0)
    tasks = [task]
    async with asyncio.timeout(10):  # the old cancel_all waits here forever
        await lifecycle.cancel_all(tasks)
    assert swallowed.is_set()
    assert task.cancelled()
    assert tasks == []
    said = [r.getMessage() for r in caplog.records if r.name == "aeroweaver_edge.runtime.lifecycle"]
    assert said == ["task stubborn still running 0.2 s after its cancel; cancelling it again"]


async def test_cancel_all_passes_on_a_task_failure() -> None:
    async def fails() -> None:
        try:
            await asyncio.sleep(3600)
        finally:
            raise RuntimeError("cleanup failed")

    task = asyncio.create_task(fails())
    await asyncio.sleep(0)
    with pytest.raises(RuntimeError, match="cleanup failed"):
        await lifecycle.cancel_all([task])


async def test_a_repeated_stop_does_not_abandon_the_tasks_being_cancelled() -> None:
    """The owner cancelled again while it waits (a second SIGTERM): it still waits for its
    tasks' clean-up, which is where a daemon holds and closes its link."""
    cleaned = asyncio.Event()

    async def slow_cleanup() -> None:
        try:
            await asyncio.sleep(3600)
        finally:
            await asyncio.sleep(0.3)  # shielded by nothing: a real clean-up's awaits
            cleaned.set()

    async def owner() -> None:
        child = asyncio.create_task(slow_cleanup())
        await asyncio.sleep(0)
        await lifecycle.cancel_all([child])

    task = asyncio.create_task(owner())
    await asyncio.sleep(0.05)
    task.cancel()  # the repeated stop, while cancel_all waits
    await asyncio.sleep(0)
    with contextlib.suppress(asyncio.CancelledError):
        await task
    assert cleaned.is_set()
