"""Lifecycles: owned background tasks, and what a process does when a party it depends on
goes away.

- ``cancel_all``: every component cancels and awaits its own tasks on the way out.
- ``TokenWatch``: the presence of one liveliness token (the simulated world's, the
  Commander's), from the mesh's liveliness events. A token that was never seen is not
  "lost": a daemon started before the world or the Commander just waits for them.
- ``run_unless_lost``: run a daemon while the world lives. When the world's token goes, the
  daemon holds at once; if the token is not back within a grace it stops (``WorldLost``).
  A partition shorter than the grace heals without a restart. Field daemons do not use
  this: losing the Commander makes them hold and wait for it, never exit.
- ``die_with_parent``: a child process started by a run gets SIGTERM when its parent dies,
  where the platform can say so (Linux ``PR_SET_PDEATHSIG``); elsewhere the world's token
  covers the same case, only later.

Timeouts are ``async with asyncio.timeout(...)``, never ``asyncio.wait_for``: on Python 3.11
``wait_for`` drops a cancellation that lands in the same loop iteration as its result
(CPython gh-86296), and a task that loses its cancel runs on while ``cancel_all`` waits for
it forever (``tests/test_async_hygiene.py`` keeps it out).
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import logging
import os
import signal
import sys
import time
from collections.abc import Awaitable, Callable, Coroutine
from typing import TYPE_CHECKING, Any, Final, TypeVar

from aeroweaver_edge.errors import RunFailed

if TYPE_CHECKING:
    from aeroweaver_edge.mesh import LivelinessEvent, LivelinessWatch, Mesh

log = logging.getLogger(__name__)
T = TypeVar("T")

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


# A cancelled task still running after this lost its cancel and is cancelled again; longer
# than any clean-up we bound (the flight's finish: 10 s), so none is cut short.
CANCEL_GRACE_S: Final = 30.0


async def cancel_all(tasks: list[asyncio.Task[Any]]) -> None:
    """Cancel every task, wait for each to finish, and empty the list.

    A task still running ``CANCEL_GRACE_S`` after its cancel lost it (a library that
    swallows cancellation, as 3.11's ``wait_for`` can): it is named in the log and
    cancelled again, instead of the shutdown waiting for it forever."""
    for t in tasks:
        t.cancel()
    for t in tasks:
        while not t.done():
            try:
                await asyncio.wait({t}, timeout=CANCEL_GRACE_S)
            except asyncio.CancelledError:  # our own stop, repeated: t has its cancel already,
                continue  # and cancelling it again would cut its clean-up short
            if not t.done():
                log.error(
                    "task %s still running %g s after its cancel; cancelling it again",
                    t.get_name(),
                    CANCEL_GRACE_S,
                )
                t.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await t  # done: its own failure, if it failed, goes to the caller as before
    tasks.clear()


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


def die_with_parent(parent_pid: int, sig: int = signal.SIGTERM) -> bool:
    """Ask the kernel to send ``sig`` to this process when its parent dies (Linux). If the
    parent is already gone (it died before we got here), send it now. Returns whether the
    kernel will tell us (False elsewhere: the caller relies on liveliness instead)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, ctypes.c_ulong(sig), 0, 0, 0) != 0:
            log.debug("prctl(PR_SET_PDEATHSIG) failed: errno %d", ctypes.get_errno())
            return False
    except (OSError, AttributeError):
        return False
    if os.getppid() != parent_pid:  # orphaned between fork and prctl: re-parented already
        os.kill(os.getpid(), sig)
    return True


__all__ = ["TokenWatch", "WorldLost", "cancel_all", "die_with_parent", "run_unless_lost"]
