"""Losing the world: a token watch over real zenoh sessions, and a run that holds when the
world's token goes, carries on if it comes back within the grace, and stops if not."""

from __future__ import annotations

import asyncio

import pytest

from aeroweaver_edge.contracts.wire import Keys
from aeroweaver_edge.mesh.presence import TokenWatch, WorldLost, run_unless_lost
from aeroweaver_edge.mesh.session import Declared
from tests.helpers.zenoh_net import ZenohNet, eventually

KEYS = Keys("lc")


async def watched(zenoh_net: ZenohNet) -> tuple[TokenWatch, Declared]:
    """A daemon-side watch of the world's token, and the world's token itself."""
    world = await zenoh_net.open("world")
    daemon = await zenoh_net.open("uav0")
    watch = TokenWatch(daemon, KEYS.alive_world)
    watch.start()
    token = world.declare_token(KEYS.alive_world)
    assert await eventually(lambda: watch.alive, 5.0)
    return watch, token


async def test_token_watch_sees_the_token_go_and_come_back(zenoh_net: ZenohNet) -> None:
    world = await zenoh_net.open("world")
    daemon = await zenoh_net.open("uav0")
    watch = TokenWatch(daemon, KEYS.alive_world)
    watch.start()
    # never seen: not lost (a daemon started before the world waits for it)
    assert await watch.wait_back(0.2) is False
    assert (watch.seen, watch.losses, watch.gone_at) == (False, 0, None)
    token = world.declare_token(KEYS.alive_world)
    assert await watch.wait_back(5.0) is True
    assert watch.seen
    assert watch.gone_at is None
    await token.aclose()
    async with asyncio.timeout(5.0):
        await watch.wait_gone()
    assert watch.losses == 1
    assert watch.gone_at is not None
    world.declare_token(KEYS.alive_world)
    assert await watch.wait_back(5.0) is True
    assert watch.gone_at is None
    await watch.aclose()


async def test_a_run_that_loses_the_world_holds_then_stops_after_the_grace(
    zenoh_net: ZenohNet,
) -> None:
    watch, token = await watched(zenoh_net)
    held = asyncio.Event()
    stopped = asyncio.Event()

    async def hold() -> None:
        held.set()

    async def forever() -> None:
        try:
            await asyncio.Event().wait()  # a daemon waiting for rounds that never come
        finally:
            stopped.set()  # its clean-up ran (cancelled, not abandoned)

    task = asyncio.create_task(run_unless_lost(forever(), watch, 0.5, hold=hold, who="uav0"))
    await asyncio.sleep(0)
    await token.aclose()
    async with asyncio.timeout(5.0):
        await held.wait()
    assert not task.done()  # holding, inside the grace
    with pytest.raises(WorldLost, match=r"uav0: the simulated world went away .* 0\.5 s"):
        async with asyncio.timeout(10.0):
            await task
    assert stopped.is_set()


async def test_a_world_back_within_the_grace_lets_the_run_finish(zenoh_net: ZenohNet) -> None:
    watch, token = await watched(zenoh_net)
    world_mesh = zenoh_net.meshes[0]
    finish = asyncio.Event()
    holds = 0

    async def hold() -> None:
        nonlocal holds
        holds += 1

    async def until_told() -> str:
        await finish.wait()
        return "done"

    task = asyncio.create_task(run_unless_lost(until_told(), watch, 30.0, hold=hold, who="uav0"))
    await token.aclose()
    assert await eventually(lambda: holds == 1, 5.0)
    world_mesh.declare_token(KEYS.alive_world)  # a partition heals / the world is back
    assert await eventually(lambda: watch.alive, 5.0)
    finish.set()
    assert await asyncio.wait_for(task, 10.0) == "done"
    assert holds == 1


async def test_cancelling_the_run_cancels_both_sides(zenoh_net: ZenohNet) -> None:
    watch, _token = await watched(zenoh_net)
    stopped = asyncio.Event()

    async def forever() -> None:
        try:
            await asyncio.Event().wait()
        finally:
            stopped.set()

    async def hold() -> None:
        return None

    task = asyncio.create_task(run_unless_lost(forever(), watch, 1.0, hold=hold, who="uav0"))
    await asyncio.sleep(0.05)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert stopped.is_set()
