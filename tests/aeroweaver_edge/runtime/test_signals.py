"""``run_until_signal``: the first SIGTERM or SIGINT cancels the command so its sessions
close; a repeated SIGTERM does not cut that clean-up, a second Ctrl-C does; after the
coroutine, ``sigterm_after`` owns SIGTERM. Real signals to this process (tests/conftest.py
puts the handlers back after each test)."""

from __future__ import annotations

import asyncio
import os
import signal
from typing import Any

import pytest

from aeroweaver_edge.runtime.signals import Stopped, run_until_signal


def _stopped_twice(signum: int, cleaned: list[str]) -> Stopped:
    async def command() -> None:
        try:
            os.kill(os.getpid(), signum)
            await asyncio.sleep(30)
        finally:
            os.kill(os.getpid(), signum)  # the same signal again, during the clean-up
            await asyncio.sleep(0.3)
            cleaned.append("closed")

    with pytest.raises(Stopped) as info:
        run_until_signal(command())
    return info.value


def test_a_repeated_sigterm_lets_the_clean_up_finish() -> None:
    cleaned: list[str] = []
    stop = _stopped_twice(signal.SIGTERM, cleaned)
    assert stop.signum == signal.SIGTERM
    assert cleaned == ["closed"]


def test_a_second_ctrl_c_cuts_the_clean_up() -> None:
    cleaned: list[str] = []
    stop = _stopped_twice(signal.SIGINT, cleaned)
    assert stop.signum == signal.SIGINT
    assert cleaned == []


def test_sigterm_after_owns_the_signal_once_the_coroutine_is_done() -> None:
    late: list[int] = []

    def after(signum: int, _frame: Any) -> None:
        late.append(signum)

    async def command() -> str:
        return "done"

    assert run_until_signal(command(), sigterm_after=after) == "done"
    assert signal.getsignal(signal.SIGTERM) is after  # not put back to the default by the loop
    os.kill(os.getpid(), signal.SIGTERM)
    assert late == [signal.SIGTERM]


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_a_stop_swallowed_before_the_loop_still_stops_the_command() -> None:
    """A SIGTERM landing in a weakref callback (an import's module-lock callback) raises
    ``Stopped`` where Python prints and drops it: the daemon went on flying. The stop is
    remembered and the loop acts on it at once, closing what the command opened."""
    import weakref

    from aeroweaver_edge.runtime.signals import forget_early_stops, stop_before_loop

    class Held:
        pass

    held = Held()
    ref = weakref.ref(held, lambda _ref: stop_before_loop(signal.SIGTERM, None))
    del held  # the callback raises Stopped; Python reports it as unraisable and goes on
    assert ref() is None
    cleaned: list[str] = []

    async def command() -> None:
        try:
            await asyncio.sleep(10)
        finally:
            cleaned.append("closed")

    try:
        with pytest.raises(Stopped) as info:
            run_until_signal(command())
    finally:
        forget_early_stops()
    assert info.value.signum == signal.SIGTERM
    assert cleaned == ["closed"]
    # remembered once: the next command runs to its end
    assert run_until_signal(asyncio.sleep(0, result="done")) == "done"
