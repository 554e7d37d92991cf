"""The hang dump names each task of a running loop and the frames it waits in, down to
the innermost coroutine (``Task.get_stack`` alone shows only the outermost)."""

from __future__ import annotations

import asyncio
import io
import threading

from tests.helpers.hang_dump import dump_asyncio_tasks


async def _innermost(gate: asyncio.Event) -> None:
    await gate.wait()


async def _outer(gate: asyncio.Event) -> None:
    await _innermost(gate)


def test_a_stuck_task_is_named_with_its_whole_await_chain() -> None:
    loop = asyncio.new_event_loop()
    gate = asyncio.Event()
    started = threading.Event()

    async def main() -> None:
        task = asyncio.create_task(_outer(gate), name="stuck-here")
        await asyncio.sleep(0)
        started.set()
        await task

    thread = threading.Thread(target=loop.run_until_complete, args=(main(),))
    thread.start()
    try:
        assert started.wait(5)
        out = io.StringIO()
        dump_asyncio_tasks("the-test", file=out)
    finally:
        loop.call_soon_threadsafe(gate.set)
        thread.join(5)
        loop.close()
    text = out.getvalue()
    assert "the-test" in text
    block = text.split("--- stuck-here", 1)[1].split("---", 1)[0]
    frames = [line.strip() for line in block.splitlines() if " in " in line]
    assert [f.rsplit(" in ", 1)[1] for f in frames[:3]] == ["_outer", "_innermost", "wait"]
