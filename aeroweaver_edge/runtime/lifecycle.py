"""Lifecycles: owned background tasks, and what a process does when a party it depends on
goes away.

- ``cancel_all``: every component cancels and awaits its own tasks on the way out.
- (a party on the mesh going away: ``mesh.presence``)
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
from typing import Any, Final, TypeVar

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


__all__ = ["cancel_all", "die_with_parent"]
