"""Presence on the mesh, and what a process does when a party it depends on goes away.

- ``TokenWatch``: the presence of one liveliness token (the simulated world's, the
  Commander's), from the mesh's liveliness events. A token that was never seen is not
  "lost": a daemon started before the world or the Commander just waits for them.
- ``run_unless_lost``: run a daemon while the world lives. When the world's token goes, the
  daemon holds at once; if the token is not back within a grace it stops (``WorldLost``).
  A partition shorter than the grace heals without a restart. Field daemons do not use
  this: losing the Commander makes them hold and wait for it, never exit.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Awaitable, Callable, Coroutine
from typing import TYPE_CHECKING, Any, TypeVar

from aeroweaver_edge.contracts.errors import RunFailed
from aeroweaver_edge.runtime.lifecycle import cancel_all

if TYPE_CHECKING:
    from aeroweaver_edge.mesh.session import LivelinessEvent, LivelinessWatch, Mesh

log = logging.getLogger(__name__)
T = TypeVar("T")


class WorldLost(RunFailed):
    """The simulated world went away and did not come back within the grace."""


class TokenWatch:
    """Whether one liveliness token is up, with waits for it to go and to come back.

    Events come from ``Mesh.watch_liveliness`` (tokens already up first), handled on the
    loop. ``gone_at`` is the monotonic time the token last went away (None while it is up
    or before it was ever seen).
    """

    def __init__(self, mesh: Mesh, key: str) -> None:
        self.key = key
        self._mesh = mesh
        self.alive = False
        self.seen = False  # the token was up at least once
        self.gone_at: float | None = None
        self.losses = 0
        self._changed = asyncio.Event()
        self._watch: LivelinessWatch | None = None

    def start(self) -> None:
        self._watch = self._mesh.watch_liveliness(self.key, on_item=self._on)

    async def aclose(self) -> None:
        if self._watch is not None:
            await self._watch.aclose()
            self._watch = None

    def _on(self, event: LivelinessEvent) -> None:
        key, alive = event
        if key != self.key or alive == self.alive:
            return
        self.alive = alive
        if alive:
            self.seen, self.gone_at = True, None
        else:
            self.gone_at = time.monotonic()
            self.losses += 1
        self._changed.set()

    async def _until(self, predicate: Callable[[], bool]) -> None:
        while not predicate():
            self._changed.clear()
            await self._changed.wait()

    async def wait_up(self) -> None:
        """Return once the token is up."""
        await self._until(lambda: self.alive)

    async def wait_gone(self) -> None:
        """Return once the token, having been up, is gone."""
        await self._until(lambda: self.seen and not self.alive)

    async def wait_back(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for the token to come back; True if it did."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(max(0.0, timeout_s)):
                await self._until(lambda: self.alive)
        return self.alive


async def run_unless_lost(
    run: Coroutine[Any, Any, T],
    watch: TokenWatch,
    grace_s: float,
    *,
    hold: Callable[[], Awaitable[None]],
    who: str,
    what: str = "the simulated world",
) -> T:
    """Run ``run`` to its end, unless ``watch``'s token goes and stays gone for ``grace_s``:
    then ``run`` is cancelled (its own clean-up holds, lands and closes) and ``WorldLost``
    is raised. ``hold`` is called as soon as the token goes."""
    main = asyncio.create_task(run, name=f"{who}-run")

    async def guard() -> float:
        while True:
            await watch.wait_gone()
            gone_at = watch.gone_at or time.monotonic()
            log.warning(
                "%s: %s went away; holding, and stopping in %.1f s unless it comes back",
                who, what, grace_s,
            )  # fmt: skip
            with contextlib.suppress(Exception):
                await hold()
            if await watch.wait_back(grace_s - (time.monotonic() - gone_at)):
                log.warning("%s: %s is back; carrying on", who, what)
                continue
            return time.monotonic() - gone_at

    guard_task = asyncio.create_task(guard(), name=f"{who}-lost-guard")
    try:
        await asyncio.wait({main, guard_task}, return_when=asyncio.FIRST_COMPLETED)
    except asyncio.CancelledError:
        await cancel_all([main, guard_task])
        raise
    if main.done():
        await cancel_all([guard_task])
        return main.result()
    away = guard_task.result()
    await cancel_all([main])
    raise WorldLost(
        f"{who}: {what} went away and did not come back within {grace_s:g} s "
        f"(gone {away:.1f} s); held and stopped"
    )


__all__ = ["TokenWatch", "WorldLost", "run_unless_lost"]
