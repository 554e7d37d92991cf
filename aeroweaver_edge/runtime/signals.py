"""Run one command's coroutine so that SIGTERM and SIGINT close every session.

It sits below ``cli.py`` and every command module (``cli.operator``, ``cli.keys``,
``sim.emulator.cli``), so a command module registers itself without importing the CLI
that imports it.
"""

from __future__ import annotations

import asyncio
import signal
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

T = TypeVar("T")


class Stopped(BaseException):
    """The operator stopped the command with a signal.

    A ``BaseException``, as ``KeyboardInterrupt`` is: a stop landing inside start-up code
    that catches ``Exception`` (importing a skill package, reading a config) must end the
    command, not be reported as that code's failure."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


_early_stops: list[int] = []


def stop_before_loop(signum: int, _frame: object) -> None:
    """SIGTERM handler for before the event loop runs: raise ``Stopped``, and remember it.

    Why remember: Python prints and drops an exception raised inside a weakref callback
    (an import's module-lock callback, say) or ``__del__``, so a stop landing there would be
    lost and the command would go on as if never signalled; ``run_until_signal`` honours a
    remembered stop as soon as its loop handles signals."""
    _early_stops.append(signum)
    raise Stopped(signum)


def forget_early_stops() -> None:
    """The command ended: a remembered stop must not reach the next one in this process."""
    _early_stops.clear()


def run_until_signal(
    coro: Coroutine[Any, Any, T],
    on_signal: Callable[[int], None] | None = None,
    *,
    sigterm_after: Callable[[int, Any], None] | None = None,
) -> T:
    """Run a coroutine; SIGTERM and SIGINT cancel it so every session is closed, then
    raise ``Stopped`` naming the signal.

    ``sigterm_after`` takes SIGTERM over from the loop as soon as the coroutine is done,
    before the loop's teardown puts the default action back: a process that can get
    SIGTERM more than once (the parent-death signal of a multithreaded parent comes once
    per exiting thread) must not die of a repeat while it is still leaving."""
    received: list[int] = []

    async def main() -> T:
        task = asyncio.current_task()
        loop = asyncio.get_running_loop()

        def stop(signum: int) -> None:
            repeat = signal.SIGTERM in received and signum == signal.SIGTERM
            if not received and on_signal is not None:
                on_signal(signum)
            received.append(signum)
            # A repeated SIGTERM (the parent-death signal comes once per exiting thread of
            # the parent; systemd may resend) must not cut the clean-up the first one
            # started: a hold, a landing, closing the link. A second Ctrl-C still does.
            if task is not None and not repeat:
                task.cancel()

        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, stop, sig)
        if _early_stops:  # a stop that came before the loop and was swallowed on the way
            stop(_early_stops[0])
            _early_stops.clear()
        try:
            return await coro
        finally:
            if sigterm_after is not None:
                loop.remove_signal_handler(signal.SIGTERM)
                signal.signal(signal.SIGTERM, sigterm_after)

    try:
        return asyncio.run(main())
    except asyncio.CancelledError:
        if received:
            raise Stopped(received[0]) from None
        raise
